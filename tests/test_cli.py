import json

import numpy as np

from explorer.cli import main


def test_presets_json(capsys):
    assert main(["presets", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["id"] for r in rows} >= {"ISB", "PMA", "PAU", "QII", "SJB", "SAN", "SCB", "WBU", "WSA", "WSU",
                                       "linear", "agile"}


def test_simulate_writes_npz(tmp_path, capsys):
    out = tmp_path / "p.npz"
    assert main(["simulate", "--preset", "WSU", "--n", "100", "--layers", "2", "--relief", "0",
                 "--seed", "1", "--out", str(out)]) == 0
    assert "simulated 200" in capsys.readouterr().out
    with np.load(out) as z:
        assert z["ground"].shape == (200, 3) and z["row"].shape == (200,)
        assert json.loads(str(z["scene_json"]))["name"] == "WSU"


def test_unknown_preset_is_a_clear_error(capsys):
    assert main(["simulate", "--preset", "NOPE", "--n", "10"]) == 2
    assert "unknown preset" in capsys.readouterr().err
