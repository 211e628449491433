"""The docs say what runs: the README's and the guides' commands, every option, every link.

* Every ``omnicam ...`` line of a fenced ``bash`` block in README.md and docs/guide-*.md is
  accepted by the real parser (views grouped as ``omnicam unwarp`` groups them), and is run for
  real (in-process, exit status 0, its outputs written) when its input files exist in a folder
  holding what ``omnicam demo`` writes (the README's own demo command, run once) plus
  ``rig.yaml``, ``frame.png`` and a 3-frame ``video.mp4`` made from it (the demo's inputs and
  calibration also at its top; the files a command writes are removed first, so each runs on
  its own). Inputs that are only named (``views/*.png``, ``photo.jpg``, a camera index) leave
  the command to the parser.
* Every ``python`` block of docs/*.md runs in such a folder.
* Every option of every subcommand is in its guide.
* Every relative link (and its ``#anchor``) of README.md and docs/*.md points at something
  that exists, and every page of docs/ is reachable from the README.
* Every repository path the docs name (``omnicam/...``, ``benchmarks/...``) exists.
* Every ``python examples/...`` or ``python benchmarks/...`` command the docs quote names an
  existing script that accepts its options (the numbers keep the commands that made them).
* docs/benchmarks.md quotes the reproduction table exactly as examples/reproduce_paper.py
  wrote it (docs/table1.md).
"""

from __future__ import annotations

import contextlib
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from omnicam.cli import build_parser, main
from omnicam.cli._common import CliError
from omnicam.cli.unwarp import view_specs

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
README = ROOT / "README.md"
GUIDES = sorted(DOCS.glob("guide-*.md"))
PAGES = [README, *sorted(DOCS.glob("*.md"))]
#: which guide documents the options of which subcommand
GUIDE_OF = {
    "calibrate": ("guide-single-image.md", "guide-chessboard.md"),
    "unwarp": ("guide-video-and-views.md",),
    "maps": ("guide-video-and-views.md",),
    "export": ("guide-video-and-views.md",),
    "info": ("guide-video-and-views.md",),
    "demo": ("guide-video-and-views.md",),
    "report": ("guide-report.md",),
}


def rel(path):
    return path.relative_to(ROOT).as_posix()


def fenced_blocks(path, language):
    """``(line number, code)`` of each fenced block of ``language`` in ``path``."""
    text = path.read_text(encoding="utf-8")
    for m in re.finditer(r"^```(\w*)\n(.*?)^```", text, re.M | re.S):
        if m.group(1) == language:
            yield text.count("\n", 0, m.start()) + 2, m.group(2)


def omnicam_commands():
    """``(id, argv)`` of every ``omnicam`` line of the bash blocks of README and the guides."""
    found = []
    for path in [README, *GUIDES]:
        for first, code in fenced_blocks(path, "bash"):
            for i, line in enumerate(code.replace("\\\n", " ").splitlines()):
                words = shlex.split(line, comments=True)
                if words and words[0] == "omnicam":
                    found.append((f"{rel(path)}:{first + i}", words[1:]))
    return found


COMMANDS = omnicam_commands()
DEMO = [argv for _, argv in COMMANDS if argv[0] == "demo"]


def parse(argv):
    """The parsed command line, with the views of ``unwarp`` and ``maps`` grouped; a malformed
    one fails the test with the parser's message."""
    try:
        args = build_parser().parse_args(argv)
        specs = view_specs(args) if args.command in ("unwarp", "maps") else []
    except CliError as e:
        pytest.fail(f"omnicam {shlex.join(argv)}: {e}")
    return args, specs


def inputs(args):
    """The input files a command reads (None: it is not run here)."""
    if args.command == "calibrate":
        named = [*args.image, args.intrinsics, args.far_lines, args.from_rig]
        named += [args.boundary_points, args.corners]
    elif args.command == "unwarp":
        named = [args.input, args.calibration]
    elif args.command in ("maps", "export", "info"):
        named = [args.calibration]
    elif args.command == "report":
        named = [args.calibration, *args.images]
    else:
        return None
    return [n for n in named if n is not None]


@contextlib.contextmanager
def cwd(path):
    before = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(before)


@pytest.fixture(scope="module")
def demo_folder(tmp_path_factory):
    """A folder after the README's ``omnicam demo`` (run once, for real), with the demo's
    files also at its top and the other inputs the guides name."""
    assert len(DEMO) == 1, "the README's demo command, once"
    folder = tmp_path_factory.mktemp("docs")
    with cwd(folder):
        assert main(DEMO[0]) == 0
    out = folder / DEMO[0][DEMO[0].index("-o") + 1]
    for name in ("mirror.png", "intrinsics.yaml", "far_lines.json", "calibration.yaml"):
        shutil.copy(out / name, folder / name)
    shutil.copy(out / "calibration.yaml", folder / "rig.yaml")
    shutil.copy(out / "mirror.png", folder / "frame.png")
    frame = cv2.imread(str(out / "mirror.png"))
    h, w = frame.shape[:2]
    video = cv2.VideoWriter(str(folder / "video.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 10, (w, h))
    for _ in range(3):
        video.write(frame)
    video.release()
    assert cv2.VideoCapture(str(folder / "video.mp4")).read()[0]
    return folder


def test_the_readme_runs_the_demo_once():
    assert len(DEMO) == 1 and DEMO[0][:2] == ["demo", "-o"]


@pytest.mark.parametrize("argv", [a for _, a in COMMANDS], ids=[i for i, _ in COMMANDS])
def test_documented_command_runs(argv, demo_folder, tmp_path, capsys):
    args, specs = parse(argv)
    needed = inputs(args)
    if needed is None or not all((demo_folder / n).exists() for n in needed):
        return  # the demo (run by the fixture), or inputs the docs only name: parsed above
    written = [s.output for s in specs] if args.command == "unwarp" else []
    if args.command in ("calibrate", "export"):
        written.append(args.output)
    work = tmp_path / "work"
    shutil.copytree(demo_folder, work)
    for name in written:  # a command run on its own: rig.yaml is an input of the others
        (work / name).unlink(missing_ok=True)
    with cwd(work):
        status = main(argv)
    out = capsys.readouterr()
    assert status == 0, f"omnicam {shlex.join(argv)} exited {status}:\n{out.out}\n{out.err}"
    for name in written:
        assert (work / name).stat().st_size > 0, name


PYTHON_BLOCKS = [
    (f"{rel(p)}:{line}", code)
    for p in sorted(DOCS.glob("*.md"))
    for line, code in fenced_blocks(p, "python")
]


@pytest.mark.parametrize("code", [c for _, c in PYTHON_BLOCKS], ids=[i for i, _ in PYTHON_BLOCKS])
def test_documented_python_runs(code, demo_folder, tmp_path, capsys):
    work = tmp_path / "work"
    shutil.copytree(demo_folder, work)
    with cwd(work):
        exec(compile(code, "docs", "exec"), {})


def subcommand_options():
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for name, parser in sub.choices.items():
        opts = [
            o
            for a in parser._actions
            for o in a.option_strings
            if o.startswith("--") and o != "--help"
        ]
        yield name, opts


def test_every_option_is_in_its_guide():
    missing = []
    for name, opts in subcommand_options():
        text = "".join((DOCS / g).read_text(encoding="utf-8") for g in GUIDE_OF[name])
        missing += [
            f"{name} {o}"
            for o in opts
            if not re.search(rf"(?<![\w-]){re.escape(o)}(?![\w-])", text)
        ]
    assert not missing, f"options no guide describes: {missing}"


def slug(heading):
    """GitHub's anchor of a heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def links(path):
    text = re.sub(r"^```.*?^```", "", path.read_text(encoding="utf-8"), flags=re.M | re.S)
    return re.findall(r"\]\(([^)\s]+)\)", text)


def anchors(path):
    text = path.read_text(encoding="utf-8")
    return {slug(h) for h in re.findall(r"^#+ (.*)$", text, re.M)}


def test_every_relative_link_points_at_something_that_exists():
    broken = []
    for page in PAGES:
        for target in links(page):
            if re.match(r"[a-z]+:", target):
                continue  # https:, mailto:
            file, _, anchor = target.partition("#")
            dest = (page.parent / file).resolve() if file else page
            if not dest.exists():
                broken.append(f"{rel(page)}: {target}")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                broken.append(f"{rel(page)}: {target} (no such heading)")
    assert not broken, broken


def test_every_page_of_docs_is_reachable_from_the_readme():
    seen, todo = set(), [README.resolve()]
    while todo:
        page = todo.pop()
        if page in seen or page.suffix != ".md" or not page.exists():
            continue
        seen.add(page)
        for target in links(page):
            file = target.partition("#")[0]
            if file and not re.match(r"[a-z]+:", file):
                todo.append((page.parent / file).resolve())
    orphans = [rel(p) for p in DOCS.glob("*.md") if p.resolve() not in seen]
    assert not orphans, f"pages no link leads to: {orphans}"


def test_every_repository_path_the_docs_name_exists():
    """``omnicam/...``, ``examples/...``, ``benchmarks/...``, ``tests/...``, ``docs/...`` in code
    spans (a module renamed must be renamed in the docs too; the CHANGELOG keeps history)."""
    stale = []
    for page in PAGES:
        if page.name == "CHANGELOG.md":
            continue
        for span in re.findall(r"`([^`\n]+)`", page.read_text(encoding="utf-8")):
            for path in re.findall(
                r"(?<![\w./-])((?:omnicam|examples|benchmarks|tests|docs)/[\w./-]*)", span
            ):
                if not path.startswith("examples/out/") and not (ROOT / path).exists():
                    stale.append(f"{rel(page)}: {path}")
    assert not stale, f"paths that do not exist: {stale}"


def quoted_scripts():
    """``{script: {options}}`` of every ``python examples/...`` or ``python benchmarks/...`` the
    docs quote, inline or in a block."""
    scripts = {}
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for m in re.finditer(r"python ((?:examples|benchmarks|tests)/[\w/]+\.py)([^`\n]*)", text):
            opts = set(re.findall(r"(?<!\S)(--[\w-]+)", m.group(2)))
            scripts.setdefault(m.group(1), set()).update(opts)
    return scripts


def test_quoted_scripts_exist_and_take_their_options():
    scripts = quoted_scripts()
    assert "examples/reproduce_paper.py" in scripts
    for script, opts in sorted(scripts.items()):
        path = ROOT / script
        assert path.is_file(), f"the docs quote {script}, which does not exist"
        if not opts:
            continue
        assert "argparse" in path.read_text(encoding="utf-8"), script
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        usage = subprocess.run(
            [sys.executable, str(path), "--help"],
            capture_output=True,
            text=True,
            check=True,
            env=env,
            cwd=ROOT,
            timeout=120,
        ).stdout
        unknown = sorted(o for o in opts if not re.search(rf"{re.escape(o)}(?![\w-])", usage))
        assert not unknown, f"{script} does not take {unknown}"


def test_benchmarks_quote_table_1_as_generated():
    generated = (DOCS / "table1.md").read_text(encoding="utf-8")
    quoted = (DOCS / "benchmarks.md").read_text(encoding="utf-8")
    rows = [line for line in generated.splitlines() if line.startswith("| ")]
    assert len(rows) >= 8
    for row in rows:
        assert row in quoted, row
