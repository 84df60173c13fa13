import numpy as np

from explorer.geometry.rotations import axis_angle_matrix, opk_from_rotation, rotation_from_opk


def test_rotation_is_product_of_elementary_rotations():
    o, p, k = 0.3, -0.2, 1.1
    rx = axis_angle_matrix([1, 0, 0], o)
    ry = axis_angle_matrix([0, 1, 0], p)
    rz = axis_angle_matrix([0, 0, 1], k)
    np.testing.assert_allclose(rotation_from_opk(o, p, k), rx @ ry @ rz, atol=1e-15)


def test_opk_round_trip_and_orthonormal():
    rng = np.random.default_rng(0)
    a = rng.uniform(-1.4, 1.4, (100, 3))
    r = rotation_from_opk(a[:, 0], a[:, 1], a[:, 2])
    np.testing.assert_allclose(np.einsum("nij,nkj->nik", r, r), np.broadcast_to(np.eye(3), r.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-14)
    np.testing.assert_allclose(np.stack(opk_from_rotation(r), axis=1), a, atol=1e-12)


def test_kappa_turns_along_track_axis_counter_clockwise_from_east():
    r = rotation_from_opk(0.0, 0.0, np.radians(90.0))
    np.testing.assert_allclose(r @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
