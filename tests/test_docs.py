"""The README quotes the reproduction table exactly as examples/reproduce_paper.py wrote it."""

import pathlib

ROOT = pathlib.Path(__file__).resolve().parent.parent


def test_readme_table_1_is_the_generated_one():
    generated = (ROOT / "docs" / "table1.md").read_text()
    readme = (ROOT / "README.md").read_text()
    rows = [line for line in generated.splitlines() if line.startswith("| ")]
    assert len(rows) >= 8
    for row in rows:
        assert row in readme, row
