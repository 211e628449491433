"""The README is a first page: short, its Python quick start runs as written, and its install
and test commands are the ones CI runs. Its ``omnicam`` commands and links: tests/test_docs.py."""

import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")


def bash_lines():
    blocks = re.findall(r"^```bash\n(.*?)^```", README, re.M | re.S)
    return [line.strip() for block in blocks for line in block.splitlines()]


def test_readme_is_at_most_150_lines():
    assert len(README.splitlines()) <= 150


def test_readme_quick_start_runs(tmp_path, monkeypatch, capsys):
    code = re.search(r"## Quick start.*?\n```python\n(.*?)```", README, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {})
    assert "chosen:" in capsys.readouterr().out
    for name in ("panorama.png", "perspective.png", "rig.yaml"):
        assert (tmp_path / name).stat().st_size > 0


def test_ci_installs_and_tests_as_the_readme_says():
    """.ci/run installs with the README's command (quietly) and runs its test command."""
    ci = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    install = [line for line in bash_lines() if line.startswith("pip install")]
    assert install == ['pip install -e ".[test]"']
    assert 'pip install --quiet -e ".[test]"' in ci
    assert "pytest" in bash_lines() and "pytest" in ci
