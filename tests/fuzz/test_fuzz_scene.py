"""Fuzzing the scene JSON reader with mutated scene files (issue 18).

Scene files of three presets (flat, agile with jitter, a DEM terrain) are mutated: a value replaced
(NaN, +-Infinity, 0, negative, huge or tiny numbers, a 400-digit integer, strings, null, lists,
objects), a key removed or duplicated, arrays shortened, the text truncated or its bytes flipped.
:meth:`explorer.scene.Scene.load` (and :func:`explorer.real.load_scene`) must either give a scene
whose lines of sight at the image centre and corners meet the ground at finite points (or NaN where
a ray misses the terrain) that project back to finite focal-plane coordinates, or raise the
package's own error (:class:`~explorer.errors.ExplorerError`); never another exception.  A file
holding NaN/Infinity in its geometry is refused (``simulate --jitter-scale inf`` wrote one).  At
least 1,000 deterministic cases.
"""

import copy
import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import event, given
from hypothesis import strategies as st

from explorer.errors import ExplorerError, InputError, SceneFileError
from explorer.geometry.exterior import Jitter
from explorer.presets import build_scene
from explorer.real import load_scene
from explorer.scene import Scene

from .conftest import FUZZ

# scenes with extreme but finite values (1e308 coefficients) are accepted and answer NaN, with numpy
# overflow warnings on the way
pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")

TMP = Path(tempfile.mkdtemp(prefix="fuzz_scene_"))
BASES = {p: json.loads(build_scene(p, **kw).to_json())
         for p, kw in (("WSU", {}), ("agile", {}), ("QII", {"relief_m": 300.0}))}
VALUES = [float("nan"), float("inf"), float("-inf"), 0, 0.0, -1.0, 1e308, -1e308, 1e-320, 10**400, -(10**400),
          "abc", "", None, True, [], {}, [1.0], {"a": 1}, 2**63, 0.5, 3]


def _leaves(obj, path=()):
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(obj, list) and obj and not all(isinstance(v, (int, float)) for v in obj):
        for i, v in enumerate(obj):
            yield from _leaves(v, (*path, i))
    yield path  # containers too (replace a whole list or object)


def _set(obj, path, value):
    for key in path[:-1]:
        obj = obj[key]
    obj[path[-1]] = value


@st.composite
def mutated_scene(draw):
    name = draw(st.sampled_from(sorted(BASES)))
    d = json.loads(json.dumps(BASES[name]))
    kind = draw(st.sampled_from(["value", "value", "value", "values", "delete", "shorten", "text"]))
    paths = [p for p in _leaves(d) if p]
    if kind in ("value", "values"):
        for _ in range(1 if kind == "value" else draw(st.integers(2, 4))):
            path = paths[draw(st.integers(0, len(paths) - 1))]
            value = draw(st.one_of(st.sampled_from(VALUES), st.floats(allow_nan=True, allow_infinity=True)))
            try:
                _set(d, path, copy.deepcopy(value))  # VALUES holds shared lists/objects: never alias them
            except (KeyError, IndexError, TypeError):
                pass  # the path went away with an earlier replacement
        text = json.dumps(d)
    elif kind == "delete":
        path = paths[draw(st.integers(0, len(paths) - 1))]
        parent = d
        for key in path[:-1]:
            parent = parent[key]
        del parent[path[-1]]
        text = json.dumps(d)
    elif kind == "shorten":
        lists = [p for p in paths if isinstance(_get(d, p), list) and _get(d, p)]
        path = lists[draw(st.integers(0, len(lists) - 1))]
        value = _get(d, path)
        _set(d, path, value[: draw(st.integers(0, len(value) - 1))])
        text = json.dumps(d)
    else:
        raw = json.dumps(d, indent=1)
        op = draw(st.sampled_from(["truncate", "flip", "duplicate_key"]))
        pos = draw(st.integers(0, len(raw) - 1))
        if op == "truncate":
            text = raw[:pos]
        elif op == "flip":
            text = raw[:pos] + chr(draw(st.integers(32, 126))) + raw[pos + 1:]
        else:  # a key line repeated: JSON keeps the last value
            lines = raw.splitlines()
            k = draw(st.integers(0, len(lines) - 1))
            text = "\n".join(lines[: k + 1] + [lines[k]] + lines[k + 1:])
        kind = op
    return name, text, kind


def _get(obj, path):
    for key in path:
        obj = obj[key]
    return obj


def _check(scene):
    rows = np.array([(scene.n_rows - 1) / 2.0, 0.0, scene.n_rows - 1.0])
    cols = np.array([(scene.n_columns - 1) / 2.0, 0.0, scene.n_columns - 1.0])
    try:
        ground = scene.image_to_ground(rows, cols)
    except ExplorerError:
        return "refused at use"
    assert not np.any(np.isinf(ground)), "ground points are finite or NaN"
    hit = np.all(np.isfinite(ground), axis=1)
    if hit.any():
        x, y = scene.focal_plane(ground[hit], scene.scanline_time(rows[hit]))
        assert np.all(np.isfinite(x)) and np.all(np.isfinite(y))
    return "used"


@FUZZ
@given(mutated_scene())
def test_mutated_scene_files_give_a_scene_or_the_packages_error(case):
    name, text, kind = case
    path = TMP / f"{name}.json"
    path.write_text(text)
    for loader in (Scene.load, load_scene):
        try:
            scene = loader(path)
        except ExplorerError as exc:
            assert str(path) in str(exc)  # names the file
            event(f"{kind}: refused")
            continue
        event(f"{kind}: {_check(scene)}")


def test_non_finite_geometry_is_refused_by_the_writer_and_the_reader(tmp_path):
    """``simulate --jitter-scale inf`` wrote ``Infinity`` into the scene JSON; now neither side accepts it."""
    scene = build_scene("agile")
    with pytest.raises(InputError, match="jitter amplitude_rad must be finite"):
        Jitter("phi", float("inf"), 1.0, 0.0)
    jitter = Jitter("phi", 1e-6, 1.0, 0.0)
    object.__setattr__(jitter, "amplitude_rad", float("inf"))  # a scene corrupted in memory
    scene.exterior.jitter = [jitter]
    with pytest.raises(SceneFileError, match=r"exterior.jitter\[0\].amplitude_rad \(inf\) is not finite"):
        scene.save(tmp_path / "bad.json")
    assert not (tmp_path / "bad.json").exists()
    good = build_scene("agile")
    good.save(tmp_path / "ok.json")
    text = (tmp_path / "ok.json").read_text()
    key = '"line_period_s": '
    start = text.index(key) + len(key)
    end = min(text.index(",", start), text.index("}", start))
    for bad, shown in (("NaN", "nan"), ("Infinity", "inf"), ("-Infinity", "-inf")):
        (tmp_path / "bad.json").write_text(text[:start] + bad + text[end:])
        with pytest.raises(SceneFileError, match=rf"bad.json: timing.line_period_s \({shown}\) is not finite"):
            Scene.load(tmp_path / "bad.json")
    # a report's NaN (no check points) in the metadata is written as null and read back
    good.metadata = {"rpc": {"check_rmse_px": float("nan")}}
    good.save(tmp_path / "meta.json")
    assert json.loads((tmp_path / "meta.json").read_text())["metadata"]["rpc"]["check_rmse_px"] is None
    assert Scene.load(tmp_path / "meta.json").metadata["rpc"]["check_rmse_px"] is None
