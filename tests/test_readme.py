"""README's quick start runs as written."""

import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parent.parent


def test_readme_quick_start_runs(tmp_path, monkeypatch, capsys):
    text = (ROOT / "README.md").read_text()
    code = re.search(r"## Quick start\s+```python\n(.*?)```", text, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {})
    assert "chosen:" in capsys.readouterr().out
    for name in ("panorama.png", "perspective.png", "rig.yaml"):
        assert (tmp_path / name).stat().st_size > 0
