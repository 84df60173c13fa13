"""viser scene builders for pushbroom geometry: model objects in, scene nodes out.

Every builder takes a viser ``SceneApi`` (``server.scene``), the
:class:`~explorer.scene.Scene` and a :class:`DisplayFrame`, adds named nodes and
returns ``{node name: handle}``.  The geometry they draw is sampled through the
scene's public API (``image_to_ground``, ``exterior.position``/``rotation``); the
pure-numpy helpers (``footprint_mesh``, ``scanline_planes``, ...) are separate so
tests check them without a server.

Display frame (``docs/explorer.md#frame``): kilometres in the local ENU frame
(``docs/conventions.md#frames``) relative to the scene centre (the ground point of
the image centre at the mean terrain height), so float32 on the client loses
nothing visible (< 1 mm at 1000 km).  The satellite is ~700 km away from a
footprint a few km wide; in the default *compressed* sensor distance every
sensor-side point (perspective centres, track, sensor frames) is translated
towards the ground along the central line of sight until the centre of the track
sits ``COMPRESSED_DISTANCE_FACTOR`` footprint diagonals from the scene centre.
The translation keeps the track's true length and shape, the true attitude and the
true viewing direction of the central scanline; ground-side geometry (terrain,
points, scanline footprints) stays exact.  Rays and scanline planes join the exact
ground geometry to the *displayed* perspective centre, so their tilt is
exaggerated.  ``sensor_distance="true"`` draws everything at true scale.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from explorer.panels import (
    ITERATION,
    SCOP_RGB,
    height_rgb,
    ramp,
)
from explorer.scene import Scene

if TYPE_CHECKING:  # pragma: no cover
    import viser

COMPRESSED_DISTANCE_FACTOR = 2.5
"""Displayed distance scene centre -> centre of the track, in footprint diagonals (compressed mode)."""
KM = 1000.0

PLANE_RGB = (90, 160, 255)
EDGE_RGB = (30, 90, 200)
SELECTED_RGB = (255, 120, 0)
TRACK_RGB = (40, 40, 40)
RAY_RGB = (255, 60, 0)


# --------------------------------------------------------------------------- frame
@dataclass(frozen=True)
class DisplayFrame:
    """Maps local ENU metres to displayed kilometres.

    Parameters
    ----------
    origin_m : ndarray, shape (3,)
        Scene centre in the local ENU frame, metres (becomes the display origin).
    sensor_shift_m : ndarray, shape (3,)
        Translation subtracted from sensor-side points (0 at true scale), metres.
    height_exaggeration : float
        Multiplies ground-side heights about the origin height (1 = true).
    diagonal_km : float
        Footprint diagonal, km (sets marker and axis sizes).
    """

    origin_m: np.ndarray
    sensor_shift_m: np.ndarray
    height_exaggeration: float = 1.0
    diagonal_km: float = 1.0

    @classmethod
    def for_scene(
        cls,
        scene: Scene,
        *,
        sensor_distance: str = "compressed",
        height_exaggeration: float = 1.0,
        factor: float = COMPRESSED_DISTANCE_FACTOR,
    ) -> DisplayFrame:
        """Display frame of a scene.

        Parameters
        ----------
        scene : Scene
        sensor_distance : {"compressed", "true"}
        height_exaggeration : float
        factor : float
            Compressed distance of the track centre, in footprint diagonals.
        """
        if sensor_distance not in ("compressed", "true"):
            raise ValueError(f"sensor_distance must be 'compressed' or 'true', got {sensor_distance!r}")
        centre = scene_centre(scene)
        fp = scene.footprint()
        diag = float(max(np.linalg.norm(fp[2] - fp[0]), np.linalg.norm(fp[3] - fp[1])))
        shift = np.zeros(3)
        if sensor_distance == "compressed":
            s_mid = scene.exterior.position(scene.scanline_time(np.array([(scene.n_rows - 1) / 2.0])))[0]
            los = s_mid - centre
            dist = float(np.linalg.norm(los))
            target = factor * diag
            if dist > target:
                shift = (1.0 - target / dist) * los
        return cls(centre, shift, float(height_exaggeration), diag / KM)

    def ground(self, points_m: np.ndarray) -> np.ndarray:
        """Ground-side points (N, 3) metres -> display km (N, 3), heights exaggerated."""
        p = (np.asarray(points_m, dtype=np.float64) - self.origin_m) / KM
        p[..., 2] *= self.height_exaggeration
        return p

    def sensor(self, points_m: np.ndarray) -> np.ndarray:
        """Sensor-side points (perspective centres) (N, 3) metres -> display km (N, 3)."""
        return (np.asarray(points_m, dtype=np.float64) - self.sensor_shift_m - self.origin_m) / KM

    @property
    def compressed(self) -> bool:
        return bool(np.any(self.sensor_shift_m != 0))


# ----------------------------------------------------------------- pure geometry
def scene_centre(scene: Scene) -> np.ndarray:
    """Ground point (3,) of the image centre on the mean-height plane, local ENU metres."""
    rc, cc = (scene.n_rows - 1) / 2.0, (scene.n_columns - 1) / 2.0
    return scene.image_to_ground(np.array([rc]), np.array([cc]), height=scene.terrain.mean_height)[0]


def _on_terrain(scene: Scene, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """image_to_ground on the terrain, falling back to the mean-height plane where a DEM is missed."""
    g = scene.image_to_ground(row, col)
    bad = ~np.isfinite(g[:, 0])
    if bad.any():
        g[bad] = scene.image_to_ground(row[bad], col[bad], height=scene.terrain.mean_height)
    return g


def footprint_mesh(scene: Scene, n: int = 41) -> tuple[np.ndarray, np.ndarray]:
    """Triangulated ground footprint of the image on the terrain.

    Parameters
    ----------
    scene : Scene
    n : int
        Nodes per image side (pixel edges included).

    Returns
    -------
    vertices : ndarray, shape (n*n, 3)
        Local ENU metres; node ``i*n + j`` is image row edge ``i``, column edge ``j``.
    faces : ndarray of int, shape (2 (n-1)^2, 3)
        Counter-clockwise seen from above.
    """
    rows = np.linspace(-0.5, scene.n_rows - 0.5, n)
    cols = np.linspace(-0.5, scene.n_columns - 0.5, n)
    rr, cc = np.repeat(rows, n), np.tile(cols, n)
    verts = _on_terrain(scene, rr, cc)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    b, c, d = a + 1, a + n, a + n + 1
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    # wind counter-clockwise seen from above (image axes map to the ground mirrored or not,
    # depending on the flight direction), so the normals point up
    f0 = verts[faces[0]]
    if np.cross(f0[1] - f0[0], f0[2] - f0[0])[2] < 0:
        faces = faces[:, ::-1]
    return verts, faces


GROUND_NODES = (41, 129)
"""Nodes per side of the ground mesh: at least 41, at most 129 (33,000 triangles: what a browser's
software WebGL still draws smoothly)."""


def ground_mesh_nodes(scene: Scene, limits: tuple[int, int] = GROUND_NODES) -> tuple[int, int | None]:
    """Nodes per side of the footprint mesh: one per DEM cell across the footprint, within ``limits``.

    Returns
    -------
    n : int
        Nodes per image side for :func:`footprint_mesh`.
    dem_cells : int or None
        DEM cells across the footprint's larger side (None for a terrain without a grid); when it
        exceeds ``n - 1`` the mesh is a decimation of the DEM.
    """
    cell = getattr(scene.terrain, "dx", None)
    if cell is None or not np.isfinite(cell) or cell <= 0:
        return limits[0], None
    fp = scene.footprint()
    span = float(max(np.ptp(fp[:, 0]), np.ptp(fp[:, 1])))
    cells = int(np.ceil(span / float(min(cell, getattr(scene.terrain, "dy", cell)))))
    return int(np.clip(cells + 1, *limits)), cells


def footprint_outline(scene: Scene, per_edge: int = 64) -> np.ndarray:
    """Image border on the terrain as segments (4 per_edge, 2, 3), local ENU metres."""
    r1, c1 = scene.n_rows - 0.5, scene.n_columns - 0.5
    s = np.linspace(0.0, 1.0, per_edge + 1)
    edges = [
        (np.full_like(s, -0.5), -0.5 + s * scene.n_columns),
        (-0.5 + s * scene.n_rows, np.full_like(s, c1)),
        (np.full_like(s, r1), c1 - s * scene.n_columns),
        (r1 - s * scene.n_rows, np.full_like(s, -0.5)),
    ]
    segs = []
    for r, c in edges:
        g = _on_terrain(scene, r, c)
        segs.append(np.stack([g[:-1], g[1:]], axis=1))
    return np.concatenate(segs)


RELIEF_SHARE = 0.05
"""Automatic height exaggeration: the terrain's relief is drawn as about this share of the footprint diagonal."""
NICE_FACTORS = (1.0, 2.0, 3.0, 5.0, 10.0, 20.0, 30.0, 50.0)
"""Automatic height exaggerations offered (the largest not above the computed one)."""
def auto_height_exaggeration(scene: Scene) -> tuple[float, float]:
    """(factor, relief_m): a height exaggeration that makes the terrain's relief visible -- about
    :data:`RELIEF_SHARE` of the footprint diagonal, rounded down to one of :data:`NICE_FACTORS` -- and the
    relief it is for.  1 on flat terrain or when the relief is already visible."""
    relief = float(scene.terrain.max_height - scene.terrain.min_height)
    fp = np.asarray(scene.footprint(), dtype=np.float64)
    diag = float(max(np.linalg.norm(fp[2] - fp[0]), np.linalg.norm(fp[3] - fp[1])))
    if not relief > 1.0 or not diag > 0:
        return 1.0, max(relief, 0.0)
    want = RELIEF_SHARE * diag / relief
    return float(max([f for f in NICE_FACTORS if f <= want], default=1.0)), relief


def track_positions(scene: Scene, n: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Perspective centres over the imaging time.

    Returns
    -------
    rows : ndarray, shape (n,)
        From the first (-0.5) to the last (rows - 0.5) scanline edge.
    positions : ndarray, shape (n, 3)
        Local ENU metres.
    """
    rows = np.linspace(-0.5, scene.n_rows - 0.5, n)
    return rows, scene.exterior.position(scene.scanline_time(rows))


def quaternion_wxyz(rot: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) -> unit quaternions (N, 4) ordered (w, x, y, z), w >= 0."""
    m = np.asarray(rot, dtype=np.float64).reshape(-1, 3, 3)
    # Shepperd's method via the symmetric 4x4 K matrix: the eigenvector of the largest eigenvalue.
    k = np.empty((m.shape[0], 4, 4))
    m00, m01, m02 = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
    m10, m11, m12 = m[:, 1, 0], m[:, 1, 1], m[:, 1, 2]
    m20, m21, m22 = m[:, 2, 0], m[:, 2, 1], m[:, 2, 2]
    k[:, 0, 0] = m00 + m11 + m22
    k[:, 1, 1] = m00 - m11 - m22
    k[:, 2, 2] = -m00 + m11 - m22
    k[:, 3, 3] = -m00 - m11 + m22
    k[:, 0, 1] = k[:, 1, 0] = m21 - m12
    k[:, 0, 2] = k[:, 2, 0] = m02 - m20
    k[:, 0, 3] = k[:, 3, 0] = m10 - m01
    k[:, 1, 2] = k[:, 2, 1] = m01 + m10
    k[:, 1, 3] = k[:, 3, 1] = m02 + m20
    k[:, 2, 3] = k[:, 3, 2] = m12 + m21
    _, vec = np.linalg.eigh(k / 3.0)
    q = vec[:, :, -1]
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q


def attitude_samples(scene: Scene, n: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sensor frames at ``n`` scanlines spread over the image.

    Returns
    -------
    rows : ndarray, shape (n,)
    positions : ndarray, shape (n, 3)
        Perspective centres, local ENU metres.
    wxyz : ndarray, shape (n, 4)
        Sensor -> object rotation (``R = Rx(omega) Ry(phi) Rz(kappa)``) as quaternions.
    """
    rows = np.linspace(0.0, scene.n_rows - 1.0, n)
    t = scene.scanline_time(rows)
    return rows, scene.exterior.position(t), quaternion_wxyz(scene.exterior.rotation(t))


def scanline_footprints(scene: Scene, rows: np.ndarray, heights: np.ndarray | float) -> np.ndarray:
    """Ground trace of whole scanlines on horizontal planes.

    Parameters
    ----------
    rows : ndarray, shape (K,)
        Fractional rows (may lie outside the image: the scanline is extended).
    heights : float or ndarray, shape (K,)
        Plane height per scanline, metres.

    Returns
    -------
    ndarray, shape (K, 2, 3)
        Ground points of the first (-0.5) and last (cols - 0.5) column edge, metres.
    """
    rows = np.asarray(rows, dtype=np.float64).ravel()
    h = np.broadcast_to(np.asarray(heights, dtype=np.float64), rows.shape)
    r2 = np.repeat(rows, 2)
    c2 = np.tile([-0.5, scene.n_columns - 0.5], rows.size)
    g = scene.image_to_ground(r2, c2, height=np.repeat(h, 2))
    return g.reshape(rows.size, 2, 3)


def scanline_planes(
    scene: Scene, rows: np.ndarray, heights: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """Central perspective planes of scanlines as triangles.

    Each plane is the triangle (perspective centre S(t(row)), ground trace of the
    first column, ground trace of the last column) -- the plane through the
    projection centre and the detector line, clipped at the ground.

    Returns
    -------
    centres : ndarray, shape (K, 3)
        Perspective centres, metres.
    ends : ndarray, shape (K, 2, 3)
        Ground ends of the scanline (see :func:`scanline_footprints`), metres.
    """
    rows = np.asarray(rows, dtype=np.float64).ravel()
    return scene.exterior.position(scene.scanline_time(rows)), scanline_footprints(scene, rows, heights)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit vertex normals (V, 3): area-weighted sums of the adjacent faces' normals."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(norm > 0, n / np.where(norm > 0, norm, 1.0), np.array([0.0, 0.0, 1.0]))


def mesh_glb(vertices: np.ndarray, faces: np.ndarray, rgb: np.ndarray) -> bytes:
    """A binary glTF 2.0 file of one triangle mesh with per-vertex colours and normals.

    Parameters
    ----------
    vertices : ndarray, shape (V, 3)
    faces : ndarray of int, shape (F, 3)
        Counter-clockwise seen from the front.
    rgb : ndarray of uint8, shape (V, 3)

    Returns
    -------
    bytes
        What viser's ``add_glb`` takes (written here instead of importing trimesh, which
        costs ~2 s at start-up).
    """
    import json
    import struct

    pos = np.ascontiguousarray(vertices, dtype=np.float32)
    nrm = vertex_normals(vertices, faces).astype(np.float32)
    col = np.ascontiguousarray(np.concatenate(
        [np.asarray(rgb, np.uint8), np.full((len(pos), 1), 255, np.uint8)], axis=1))
    idx = np.ascontiguousarray(faces, dtype=np.uint32).ravel()
    blobs = [pos.tobytes(), nrm.tobytes(), col.tobytes(), idx.tobytes()]
    views, offset = [], 0
    for k, blob in enumerate(blobs):
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(blob),
                      "target": 34963 if k == 3 else 34962})
        offset += (len(blob) + 3) // 4 * 4
    bin_chunk = b"".join(b + b"\0" * ((-len(b)) % 4) for b in blobs)
    doc = {
        "asset": {"version": "2.0", "generator": "pushbroom-explorer"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "COLOR_0": 2},
                                    "indices": 3, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0,
                                                "roughnessFactor": 1.0}, "doubleSided": True}],
        "buffers": [{"byteLength": len(bin_chunk)}],
        "bufferViews": views,
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3",
             "min": pos.min(0).tolist(), "max": pos.max(0).tolist()},
            {"bufferView": 1, "componentType": 5126, "count": len(pos), "type": "VEC3"},
            {"bufferView": 2, "componentType": 5121, "normalized": True, "count": len(pos), "type": "VEC4"},
            {"bufferView": 3, "componentType": 5125, "count": len(idx), "type": "SCALAR"},
        ],
    }
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * ((-len(js)) % 4)
    total = 12 + 8 + len(js) + 8 + len(bin_chunk)
    return b"".join([struct.pack("<4sII", b"glTF", 2, total), struct.pack("<I4s", len(js), b"JSON"), js,
                     struct.pack("<I4s", len(bin_chunk), b"BIN\0"), bin_chunk])


SCP_COVER = 0.75
"""``point_size`` of a check point's marker in SCP spacings.  viser draws a point ``point_size / (tan(fov / 2)
depth)`` canvas heights wide -- twice its projected size (its shader takes ``tan(fov / 2) depth``, half the
frustum, for the frustum's height) --, so 0.75 draws round markers 1.5 spacings wide: a grid of them leaves no
gap (from 2 ** 0.5 on).  Smaller markers let the ground show between them wherever the camera is close
enough for a spacing to span more than a pixel (a closer camera then *washes out* the residual colours: the
former 0.45 drew 0.9 spacings, 64 % of the footprint); from farther away each marker is one pixel anyway."""
VISER_POINT_SCALE = 2.0
"""Drawn diameter of a viser point over its ``point_size`` projected through the camera (see SCP_COVER)."""


def point_size_km(frame: DisplayFrame, n_points: int, fraction: float = 0.45) -> float:
    """Marker size (km) of about ``fraction`` of the spacing of ``n_points`` spread over the footprint."""
    return float(fraction * frame.diagonal_km / np.sqrt(2.0 * max(n_points, 1)))


# ---------------------------------------------------------------------- builders
Handles = dict[str, Any]


def add_ground(api: viser.SceneApi, scene: Scene, frame: DisplayFrame, *, n: int = 41, note: str = "") -> Handles:
    """Footprint mesh coloured by height (height ramp with relief, flat colour without) + outline.

    Parameters
    ----------
    note : str
        Text written in the view at a corner of the footprint (the height exaggeration); "" for none.

    Nodes: ``/ground/surface`` (mesh, vertex colours), ``/ground/outline`` (segments), ``/ground/note``
    (label at the first row's last-column corner; :func:`footprint_corners` gives the others).
    """
    verts_m, faces = footprint_mesh(scene, n)
    lo, hi = scene.terrain.min_height, scene.terrain.max_height
    rgb = height_rgb(verts_m[:, 2], lo, hi if hi - lo > 1e-6 else lo)  # flat colour without relief
    out: Handles = {}
    out["/ground/surface"] = api.add_glb("/ground/surface", mesh_glb(frame.ground(verts_m), faces, rgb),
                                         cast_shadow=False, receive_shadow=False)
    seg = frame.ground(footprint_outline(scene).reshape(-1, 3)).reshape(-1, 2, 3)
    out["/ground/outline"] = api.add_line_segments(
        "/ground/outline", seg, (20, 20, 20), thickness=2.0, thickness_units="screen")
    if note:
        out["/ground/note"] = api.add_label("/ground/note", note, position=frame.ground(footprint_corners(scene))[1],
                                            anchor="bottom-left")
    return out


def footprint_corners(scene: Scene) -> np.ndarray:
    """The image's outer corners on the terrain (4, 3), local ENU metres: (first row, first column), (first
    row, last column), (last row, last column), (last row, first column), at pixel edges."""
    r1, c1 = scene.n_rows - 0.5, scene.n_columns - 0.5
    return _on_terrain(scene, np.array([-0.5, -0.5, r1, r1]), np.array([-0.5, c1, c1, -0.5]))


def add_orbit(api: viser.SceneApi, scene: Scene, frame: DisplayFrame, *, n_frames: int = 5) -> Handles:
    """Satellite track over the imaging time, sensor frames at sampled scanlines, flight direction.

    Nodes: ``/orbit/track`` (Catmull-Rom spline), ``/orbit/sensor_frames`` (batched axes:
    x red = along track, y green = across track, z blue = away from the ground),
    ``/orbit/direction`` (arrow), ``/orbit/flight_label``, ``/orbit/track_label``.
    """
    rows, pos = track_positions(scene)
    track = frame.sensor(pos)
    out: Handles = {}
    out["/orbit/track"] = api.add_spline_catmull_rom(
        "/orbit/track", track, thickness=3.0, thickness_units="screen", color=TRACK_RGB)
    _, fpos, wxyz = attitude_samples(scene, n_frames)
    axes_len = 0.12 * frame.diagonal_km
    out["/orbit/sensor_frames"] = api.add_batched_axes(
        "/orbit/sensor_frames", wxyz, frame.sensor(fpos), axes_length=axes_len,
        axes_radius=axes_len * 0.06)
    direction = track[-1] - track[-2]
    direction /= np.linalg.norm(direction)
    tip = track[-1] + 0.25 * frame.diagonal_km * direction
    out["/orbit/direction"] = api.add_arrows(
        "/orbit/direction", np.stack([track[-1], tip])[None], (40, 40, 40),
        shaft_radius=0.006 * frame.diagonal_km, head_radius=0.02 * frame.diagonal_km,
        head_length=0.06 * frame.diagonal_km)
    out["/orbit/flight_label"] = api.add_label("/orbit/flight_label", "flight direction", position=tip,
                                          anchor="bottom-left")
    what = "compressed distance" if frame.compressed else "true scale"
    out["/orbit/track_label"] = api.add_label(
        "/orbit/track_label", f"satellite track, row 0 ({what})", position=track[0],
        anchor="top-right")
    return out


PLANE_TEXTURE_PX = 256
"""Texels along the longer side of a scanline plane's texture (its edges are drawn as lines on top)."""


def triangle_texture(
    triangle: np.ndarray, rgb: tuple[int, int, int], opacity: float, px: int = PLANE_TEXTURE_PX
) -> tuple[np.ndarray, float, float, np.ndarray, np.ndarray]:
    """A flat triangle as an image in its own plane: what viser's ``add_image`` draws unlit.

    viser draws an image as a rectangle ``render_width`` x ``render_height`` centred on its node, image
    column ``c`` along the node's +x and image row ``r`` along its +y (row 0 at -y: the client turns the
    plane half a turn about x), texel ``(r, c)`` at ``(-w/2 + (c + 1/2) w / W, -h/2 + (r + 1/2) h / H, 0)``.

    Parameters
    ----------
    triangle : ndarray, shape (3, 3)
        Vertices in the display frame (km); not degenerate.
    rgb : (int, int, int)
        Colour inside the triangle.
    opacity : float
        Alpha inside the triangle (0..1); outside the texels are fully transparent.
    px : int
        Texels along the rectangle's longer side.

    Returns
    -------
    rgba : ndarray of uint8, shape (H, W, 4)
    width, height : float
        The rectangle's size in the display frame (km): the triangle's bounding box in its plane.
    position : ndarray, shape (3,)
        The rectangle's centre (km).
    rotation : ndarray, shape (3, 3)
        Node -> display frame: columns x (along the triangle's last edge, vertex 1 to 2), y, and the
        plane's normal.
    """
    tri = np.asarray(triangle, dtype=np.float64).reshape(3, 3)
    u = tri[2] - tri[1]
    normal = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    if np.linalg.norm(u) == 0 or np.linalg.norm(normal) == 0:
        raise ValueError("degenerate triangle")
    u /= np.linalg.norm(u)
    normal /= np.linalg.norm(normal)
    rot = np.stack([u, np.cross(normal, u), normal], axis=1)
    uv = (tri - tri[0]) @ rot[:, :2]
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    w, h = hi - lo
    n_w = max(2, int(round(px * min(1.0, w / h))))
    n_h = max(2, int(round(px * min(1.0, h / w))))
    x, y = np.meshgrid(lo[0] + (np.arange(n_w) + 0.5) * w / n_w, lo[1] + (np.arange(n_h) + 0.5) * h / n_h)
    cross = [(b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0])
             for a, b in ((uv[0], uv[1]), (uv[1], uv[2]), (uv[2], uv[0]))]
    inside = np.all([c >= 0 for c in cross], axis=0) | np.all([c <= 0 for c in cross], axis=0)
    rgba = np.zeros((n_h, n_w, 4), np.uint8)
    rgba[inside, :3] = np.asarray(rgb, np.uint8)
    rgba[inside, 3] = int(round(255 * float(np.clip(opacity, 0.0, 1.0))))
    centre = tri[0] + rot[:, :2] @ ((lo + hi) / 2.0)
    return rgba, float(w), float(h), centre, rot


def add_scanline_planes(
    api: viser.SceneApi,
    scene: Scene,
    frame: DisplayFrame,
    rows: np.ndarray,
    heights: np.ndarray | float,
    names: list[str],
    *,
    opacity: float = 0.22,
    filled: list[int] | None = None,
) -> Handles:
    """The central perspective planes of several scanlines, translucent.

    Each plane is filled by an unlit image of its triangle (:func:`triangle_texture`): a lit translucent
    mesh cost a browser's software WebGL ~10x more per frame (the planes reach the sensor and cover much of
    the view) and every frame of the explorer paid it.

    Parameters
    ----------
    rows : ndarray, shape (K,)
    heights : float or ndarray (K,)
        Height of the ground plane each triangle is clipped at, metres.
    names : list of str, length K
        Label text for each plane (shown at its first-column ground end; "" for none).
    filled : list of int, optional
        The planes drawn filled (default: all); the others are drawn by their outline only (the fill is what a
        software WebGL pays for, per frame, over the whole area the plane covers on screen).

    Nodes: ``/scanlines/planes/<k>`` (plane k's image, double-sided, for each filled k), ``/scanlines/edges``
    (every triangle's outline), ``/scanlines/labels/<k>``.
    """
    centres, ends = scanline_planes(scene, rows, heights)
    c = frame.sensor(centres)
    e = frame.ground(ends.reshape(-1, 3)).reshape(-1, 2, 3)
    tri = np.concatenate([c[:, None, :], e], axis=1)
    out: Handles = {}
    for k in range(len(tri)) if filled is None else sorted(set(filled)):
        rgba, w, h, centre, rot = triangle_texture(tri[k], PLANE_RGB, opacity)
        key = f"/scanlines/planes/{k}"
        out[key] = api.add_image(key, rgba, w, h, format="png", position=centre, wxyz=quaternion_wxyz(rot)[0],
                                 cast_shadow=False, receive_shadow=False)
    seg = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]], axis=0)
    out["/scanlines/edges"] = api.add_line_segments(
        "/scanlines/edges", seg, EDGE_RGB, thickness=1.5, thickness_units="screen")
    for i, name in enumerate(names):
        if not name:
            continue
        key = f"/scanlines/labels/{i}"
        out[key] = api.add_label(key, name, position=e[i, 0], anchor="center-right")
    return out


def add_points(
    api: viser.SceneApi,
    name: str,
    frame: DisplayFrame,
    points_m: np.ndarray,
    colors: np.ndarray | tuple[int, int, int],
    *,
    size_km: float,
    shape: Literal["square", "diamond", "circle", "rounded", "sparkle"] = "circle",
) -> Handles:
    """A point cloud of ground-side points (float32 km; colours (N, 3) uint8 or one RGB)."""
    pts = frame.ground(points_m).astype(np.float32)
    col = np.asarray(colors, dtype=np.uint8)
    return {name: api.add_point_cloud(name, pts, col, point_size=size_km, point_shape=shape,
                                      precision="float32", point_shading="flat")}


def scop_point_size_km(frame: DisplayFrame, n: int) -> float:
    """The SCOP markers' size: 1.2 % of the footprint diagonal, smaller when they are many (30 % of their
    spacing), so 1,000 SCOPs leave the ground visible."""
    return min(point_size_km(frame, n, 0.3), 0.012 * frame.diagonal_km)


def add_scops(api: viser.SceneApi, frame: DisplayFrame, ground_m: np.ndarray) -> Handles:
    """SCOPs as gold points, node ``/points/scops`` (size :func:`scop_point_size_km`)."""
    return add_points(api, "/points/scops", frame, ground_m, SCOP_RGB,
                      size_km=scop_point_size_km(frame, len(ground_m)), shape="diamond")


def move_scops(handle: Any, frame: DisplayFrame, ground_m: np.ndarray) -> None:
    """Put the SCOP cloud made by :func:`add_scops` on other SCOPs in place: only the points and their size are
    sent (its single colour, its shape and so its material stay; a browser drawing WebGL in software re-links a
    new cloud's shader program)."""
    handle.points = frame.ground(np.asarray(ground_m, dtype=np.float64)).astype(np.float32)
    handle.point_size = float(scop_point_size_km(frame, len(ground_m)))


def add_selection(
    api: viser.SceneApi,
    scene: Scene,
    frame: DisplayFrame,
    ground_m: np.ndarray,
    best_row: float,
    trace_rows: np.ndarray | None,
    *,
    label: str = "",
    max_labels: int = 8,
) -> Handles:
    """A selected ground point, its ray to the perspective centre of its best scanline, and the
    scanlines a search visited.

    Parameters
    ----------
    ground_m : ndarray, shape (3,)
    best_row : float
        The exact best scanline of the point.
    trace_rows : ndarray, shape (K,), optional
        Candidate rows per iteration, in order; drawn as the scanlines' ground traces at the
        point's height coloured first (yellow) to last (purple), the first and last
        ``max_labels // 2`` labelled with the iteration number.
    label : str
        Text at the point.

    Nodes: ``/selected/point``, ``/selected/ray``, ``/selected/trace`` (when a trace is given),
    ``/selected/trace_labels/<k>``, ``/selected/label``.
    """
    p = np.asarray(ground_m, dtype=np.float64).reshape(1, 3)
    pd = frame.ground(p)
    out: Handles = {}
    size = 0.02 * frame.diagonal_km
    out["/selected/point"] = api.add_icosphere("/selected/point", radius=size, color=SELECTED_RGB,
                                               position=pd[0], cast_shadow=False)
    s = frame.sensor(scene.exterior.position(scene.scanline_time(np.array([best_row]))))
    out["/selected/ray"] = api.add_line_segments(
        "/selected/ray", np.stack([pd[0], s[0]])[None], RAY_RGB, thickness=2.5,
        thickness_units="screen")
    out["/selected/label"] = api.add_label("/selected/label", label or f"row {best_row:.2f}",
                                            position=pd[0], anchor="bottom-left")
    if trace_rows is not None:
        tr = np.asarray(trace_rows, dtype=np.float64).ravel()
        tr = tr[np.isfinite(tr)]
        if tr.size:
            ends = frame.ground(scanline_footprints(scene, tr, p[0, 2]).reshape(-1, 3)).reshape(-1, 2, 3)
            u = np.linspace(0.0, 1.0, tr.size) if tr.size > 1 else np.ones(1)
            col = ramp(u, ITERATION, 0.0, 1.0)
            out["/selected/trace"] = api.add_line_segments(
                "/selected/trace", ends, np.repeat(col[:, None, :], 2, axis=1), thickness=2.0,
                thickness_units="screen")
            half = max_labels // 2
            show = [k for k in range(tr.size) if k < half or k >= tr.size - half]
            for k in show:
                key = f"/selected/trace_labels/{k}"
                out[key] = api.add_label(key, str(k + 1), position=ends[k, 1], anchor="center-left",
                                         font_screen_scale=0.8)
    return out


__all__ = [
    "COMPRESSED_DISTANCE_FACTOR", "GROUND_NODES", "SCP_COVER", "VISER_POINT_SCALE",
    "DisplayFrame", "add_ground", "add_orbit", "add_points",
    "ground_mesh_nodes",
    "add_scanline_planes", "add_scops", "move_scops", "scop_point_size_km",
    "triangle_texture", "PLANE_TEXTURE_PX", "add_selection", "attitude_samples",
    "footprint_mesh",
    "footprint_corners", "footprint_outline", "mesh_glb", "point_size_km", "quaternion_wxyz", "scanline_footprints",
    "scanline_planes", "scene_centre", "track_positions", "vertex_normals", "auto_height_exaggeration",
]
