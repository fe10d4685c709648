"""``sphrelax relax`` says what stopped it (issue 31, item 9): the default step cap is named as such, not as a
``--steps`` the user never gave."""
import json

from ase_sphrelax.cli import main
from ase_sphrelax.cli import relax as relax_cli


def _stop_reason(tmp_path, *args):
    code = main(["relax", "--dx", str(1 / 40), "--out", str(tmp_path), *args])
    return code, json.loads((tmp_path / "summary.json").read_text())["stop_reason"]


def test_the_default_cap_is_not_called_steps(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(relax_cli, "DEFAULT_STEPS", 4)
    _, reason = _stop_reason(tmp_path / "default")
    assert reason == "reached the default step cap 4 (no --steps given)" and "--steps 4" not in reason
    assert "stopped after 4 steps: reached the default step cap 4" in capsys.readouterr().out
    _, reason = _stop_reason(tmp_path / "given", "--steps", "4")
    assert reason == "reached --steps 4"
