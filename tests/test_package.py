"""The Layout of docs/architecture.md is the package: every module has its row, and the layers
it lists are the way the imports run (every import counted, function-level ones included)."""

import re
import subprocess
import sys
from pathlib import Path

from test_layers import ROOT, import_graph

ARCHITECTURE = (ROOT.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
LAYOUT = ARCHITECTURE.split("## Layout", 1)[1].split("\n## ", 1)[0]
PACKAGES = tuple(sorted(p.name for p in ROOT.iterdir() if (p / "__init__.py").is_file()))


def unit(module):
    """A module's unit in the layers: its package under omnicam, else its file."""
    parts = module.split(".")
    if len(parts) > 1 and parts[1] in PACKAGES:
        return parts[1] + "/"
    return (parts[1] if len(parts) > 1 else "__init__") + ".py"


def readme_layers():
    """``{unit: layer}`` from the Layout's numbered list (an item may run over several lines)."""
    layers, current = {}, None
    for line in LAYOUT.splitlines():
        m = re.match(r"(\d+)\. (.*)", line)
        if m:
            current, text = int(m.group(1)), m.group(2)
        elif current is not None and line.startswith("   "):
            text = line
        else:
            current = None
            continue
        for name in re.findall(r"`([A-Za-z_0-9]+(?:\.py|/))`", text):
            layers.setdefault(name, current)
    return layers


def test_every_import_runs_down_the_readmes_layers():
    layers = readme_layers()
    layers["__init__.py"] = 0  # the package's face: it imports nothing until a name is used
    graph = import_graph()
    units = {unit(m) for m in graph} - {"__init__.py"}
    assert units <= set(layers), (
        f"not in the layers of docs/architecture.md: {sorted(units - set(layers))}"
    )
    upward = [
        (a, b)
        for a, targets in graph.items()
        for b in targets
        if unit(a) != "__init__.py" and unit(a) != unit(b) and layers[unit(b)] >= layers[unit(a)]
    ]
    assert not upward, f"imports that do not run down the layers of docs/architecture.md: {upward}"


def test_every_module_has_its_row_in_the_layout_table():
    rows = [line for line in LAYOUT.splitlines() if line.startswith("| `omnicam/")]
    covered = set()
    for row in rows:
        cell = row.split("|")[1]
        names = [
            n
            for n in re.findall(r"`([^`]+)`", cell)
            if n.endswith(".py") or n.startswith("omnicam/")
        ]
        folder = str(Path(names[0]).parent) if not names[0].endswith("/") else names[0]
        for name in names:
            path = name if name.startswith("omnicam/") else f"{folder}/{name}"
            covered.add(path.rstrip("/"))
    missing = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT.parent).as_posix()
        if path.name == "__init__.py" and rel != "omnicam/calibration/__init__.py":
            continue
        if not any(rel == c or rel.startswith(c + "/") for c in covered):
            missing.append(rel)
    assert not missing, f"modules without a row in the Layout of docs/architecture.md: {missing}"
    for c in covered:
        assert (ROOT.parent / c).exists(), (
            f"the Layout of docs/architecture.md names {c}, which does not exist"
        )


def test_importing_omnicam_has_no_side_effect():
    code = (
        "import signal, sys; sys.argv[0] = 'omnicam'; before = signal.getsignal(signal.SIGINT); "
        "import omnicam; assert signal.getsignal(signal.SIGINT) is before; "
        "assert 'cv2' not in sys.modules and 'numpy' not in sys.modules, 'loaded eagerly'; "
        "omnicam.MisalignedHyperbolicCamera; omnicam.calibrate_pattern"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
