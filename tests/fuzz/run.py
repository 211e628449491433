"""Fuzz omnicam: file mutants, API and CLI arguments, corrupt media, SIGINT, full/read-only disks.

One command, seeded and bounded::

    python tests/fuzz/run.py                 # the full run (>= 1500 cases), prints the counts
    python tests/fuzz/run.py --quick         # a few hundred cases, under a minute (CI)
    python tests/fuzz/run.py --seed 7 -v     # another seed, every bad case in full

Every case runs in a worker subprocess (so a SIGSEGV or an abort inside OpenCV is caught and
classified, and the worker restarted), with its stdout and stderr captured at the file
descriptor level and a timeout. An outcome is **ok** when the call returned a valid result or
raised the documented exception type (``ValueError`` or ``FileNotFoundError``) with a message
naming the argument or the file; for the CLI an exit status 0, 1 or 2 (130 after SIGINT) with
one ``omnicam: error: ...`` line. It is **bad** for a crash or signal, a hang past the timeout,
another exception type, a message that names neither argument nor file, any other stderr output
(OpenCV's own lines, Python warnings, tracebacks), a value loaded differently from what the file
says, an old file changed or lost by a failed save, a temporary file left behind, an interrupted
save or video that destroyed an earlier output.

Full-disk and read-only cases mount a small tmpfs (``mount -t tmpfs -o size=64k``) and need
root; without it they are skipped with a message. Permission cases run in a second worker as
user ``nobody`` (root only). The exit status is 1 if any case was bad.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import math
import os
import random
import re
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
TEMP_MARK = ".omnicam-tmp-"
ALLOWED = (ValueError, FileNotFoundError)


# ==============================================================================================
# Files: our own writers (sharing nothing with omnicam.formats) and the mutation operators
# ==============================================================================================
def _num(v):
    return repr(float(v)) if isinstance(v, float) else str(v)


def base_fields(cam):
    """The fields of a calibration file of ``cam`` as tokens: name -> value spec."""
    fields = {
        "format_version": ("raw", "1"),
        "model": ("str", "misaligned_hyperbolic"),
        "mirror": (
            "map",
            {
                "a": _num(cam.mirror.a),
                "b": _num(cam.mirror.b),
                "rim_radius": _num(cam.mirror.rim_radius),
            },
        ),
        "K": ("mat", 3, 3, "d", [_num(v) for v in cam.K.ravel()]),
        "rvec": ("mat", 3, 1, "d", [_num(v) for v in cam.rvec]),
        "tvec": ("mat", 3, 1, "d", [_num(v) for v in cam.tvec]),
        "image_size": ("seq", [str(v) for v in cam.image_size]),
    }
    if cam.D is not None:
        fields["D"] = ("mat", 1, len(cam.D), "d", [_num(v) for v in cam.D])
    return fields


def render(fields, fmt):
    """Text of a FileStorage file in ``fmt`` (yaml, xml, json) from value specs."""
    out = []
    if fmt == "yaml":
        out.append("%YAML:1.0\n---\n")
        for name, v in fields.items():
            kind = v[0]
            if kind in ("raw", "str"):
                out.append(f"{name}: {v[1] if kind == 'raw' else json.dumps(v[1])}\n")
            elif kind == "map":
                out.append(f"{name}:\n" + "".join(f"   {k}: {x}\n" for k, x in v[1].items()))
            elif kind == "seq":
                out.append(f"{name}: [ {', '.join(v[1])} ]\n")
            else:
                _, r, c, dt, data = v
                out.append(
                    f"{name}: !!opencv-matrix\n   rows: {r}\n   cols: {c}\n   dt: {dt}\n"
                    f"   data: [ {', '.join(data)} ]\n"
                )
    elif fmt == "xml":
        out.append('<?xml version="1.0"?>\n<opencv_storage>\n')
        for name, v in fields.items():
            kind = v[0]
            if kind in ("raw", "str"):
                out.append(f"<{name}>{v[1] if kind == 'raw' else v[1]}</{name}>\n")
            elif kind == "map":
                out.append(
                    f"<{name}>\n"
                    + "".join(f"  <{k}>{x}</{k}>\n" for k, x in v[1].items())
                    + f"</{name}>\n"
                )
            elif kind == "seq":
                out.append(f"<{name}>\n  {' '.join(v[1])}</{name}>\n")
            else:
                _, r, c, dt, data = v
                out.append(
                    f'<{name} type_id="opencv-matrix">\n  <rows>{r}</rows>\n  <cols>{c}'
                    f"</cols>\n  <dt>{dt}</dt>\n  <data>\n    {' '.join(data)}</data></"
                    f"{name}>\n"
                )
        out.append("</opencv_storage>\n")
    else:
        items = []
        for name, v in fields.items():
            kind = v[0]
            if kind == "raw":
                items.append(f'    "{name}": {v[1]}')
            elif kind == "str":
                items.append(f'    "{name}": {json.dumps(v[1])}')
            elif kind == "map":
                pairs = ", ".join(f'"{k}": {x}' for k, x in v[1].items())
                items.append(f'    "{name}": {{ ' + pairs + " }")
            elif kind == "seq":
                items.append(f'    "{name}": [ {", ".join(v[1])} ]')
            else:
                _, r, c, dt, data = v
                items.append(
                    f'    "{name}": {{ "type_id": "opencv-matrix", "rows": {r}, "cols": '
                    f'{c}, "dt": "{dt}", "data": [ {", ".join(data)} ] }}'
                )
        out.append("{\n" + ",\n".join(items) + "\n}\n")
    return "".join(out)


NAN_TOKENS = {
    "yaml": [".nan", ".inf", "-.inf", ".NaN"],
    "xml": [".nan", ".inf", "-.inf"],
    "json": ["NaN", "Infinity", "-Infinity"],
}
EXTREME = [
    "1e300",
    "-1e300",
    "1e-300",
    "0",
    "-0.0",
    "1e12",
    "-1",
    "583",
    "2147483648",
    "1e400",
    "-1e400",
    "4294967297",
    "1e7",
    "1e-2",
    "99999999999999999999999",
]
WRONG = ['"abc"', "abc", "[ 1, 2 ]", "{ }", "true", "null", "", '""', "[ ]", "- 1"]


def semantic_mutant(rnd, fields, fmt):
    """A field-level mutation: (fields, description, must_refuse)."""
    f = {
        k: (
            tuple(v[:-1])
            + (
                list(v[-1])
                if isinstance(v[-1], list)
                else dict(v[-1])
                if isinstance(v[-1], dict)
                else v[-1],
            )
        )
        for k, v in fields.items()
    }
    name = rnd.choice(list(f))
    ops = ["delete", "wrong", "nan", "extreme", "dt", "shape", "swap", "scale"]
    if "mirror" in f:  # a calibration file
        ops += ["posture", "model"]
    op = rnd.choice(ops)
    spec = f[name]
    refuse = False
    if op == "delete":
        del f[name]
        refuse = name not in ("D", "image_size")
    elif op == "model":
        bad = rnd.choice(["parabolic", "misaligned_hyperbolic ", "MISALIGNED_HYPERBOLIC", "", "1"])
        f["model"] = ("str", bad)
        refuse = not (fmt == "xml" and bad.strip() == "misaligned_hyperbolic")  # xml strips
    elif op == "posture":  # physically impossible cameras, all must be refused
        choice = rnd.choice(["upper_focus", "behind", "flipped", "inside", "far_side"])
        if choice == "upper_focus":
            c = math.hypot(float(f["mirror"][1]["a"]), float(f["mirror"][1]["b"]))
            f["rvec"] = ("mat", 3, 1, "d", ["0.", "0.", "0."])
            f["tvec"] = ("mat", 3, 1, "d", ["0.", "0.", _num(-c)])
        elif choice == "behind":
            f["tvec"] = ("mat", 3, 1, "d", ["0.", "0.", "-100."])
            f["rvec"] = ("mat", 3, 1, "d", ["0.", "0.", "0."])
        elif choice == "flipped":
            f["rvec"] = ("mat", 3, 1, "d", [_num(math.pi), "0.", "0."])
        elif choice == "inside":  # camera inside the hyperboloid, above the sheet
            f["rvec"] = ("mat", 3, 1, "d", ["0.", "0.", "0."])
            f["tvec"] = ("mat", 3, 1, "d", ["0.", "0.", "-1000."])
        else:
            f["rvec"] = ("mat", 3, 1, "d", ["0.", _num(math.pi / 2 + 0.3), "0."])
        refuse = True
        return f, f"posture:{choice}", refuse
    elif spec[0] == "mat":
        _, r, c, dt, data = spec
        data = list(data)
        i = rnd.randrange(len(data))
        if op == "wrong":
            data[i] = rnd.choice(WRONG)
        elif op == "nan":
            data[i] = rnd.choice(NAN_TOKENS[fmt])
            refuse = True
        elif op == "extreme":
            data[i] = rnd.choice(EXTREME)
        elif op == "dt":
            dt = rnd.choice(["u", "c", "w", "s", "i", "f", "3d", "x", "", "dd", "U"])
            if rnd.random() < 0.5:
                data = [str(int(float(x))) if abs(float(x)) < 1e9 else x for x in data]
                data[i] = rnd.choice(["583", "-1", "70000", "255", "128", "3.5e38", "4e9"])
        elif op == "shape":
            r, c = rnd.choice(
                [
                    (1, 9),
                    (9, 1),
                    (2, 2),
                    (0, 3),
                    (3, 0),
                    (-1, 3),
                    (100000, 1),
                    (3, 4),
                    (1, len(data)),
                    (2147483647, 2),
                ]
            )
        elif op == "swap":
            data = data[::-1]
        else:
            data = [
                _num(float(x) * rnd.choice([1e-9, 1e9, 1e6, -1])) if _isnum(x) else x for x in data
            ]
        f[name] = ("mat", r, c, dt, data)
    elif spec[0] == "map":
        m = dict(spec[1])
        k = rnd.choice(list(m))
        if op == "delete" or (op == "swap" and len(m) > 1):
            del m[k]
            refuse = True
        elif op == "wrong":
            m[k] = rnd.choice(WRONG)
            refuse = True
        elif op == "nan":
            m[k] = rnd.choice(NAN_TOKENS[fmt])
            refuse = True
        else:
            m[k] = rnd.choice(EXTREME + ["1e-4", "2e6"])
            refuse = m[k] in (
                "1e300",
                "-1e300",
                "1e-300",
                "0",
                "-0.0",
                "1e12",
                "-1",
                "1e400",
                "-1e400",
                "99999999999999999999999",
                "1e-4",
                "2e6",
                "4294967297",
                "1e7",
                "2147483648",
            )
        f[name] = ("map", m)
    elif spec[0] == "seq":
        vals = list(spec[1])
        choice = rnd.choice(["inf", "float", "huge", "neg", "short", "long", "str"])
        vals = {
            "inf": [NAN_TOKENS[fmt][1], vals[1]],
            "float": ["640.5", vals[1]],
            "huge": ["1000000", "1000000"],
            "neg": ["-640", vals[1]],
            "short": vals[:1],
            "long": vals + ["3"],
            "str": ['"640"', vals[1]],
        }[choice]
        refuse = True
        f[name] = ("seq", vals)
    else:
        f[name] = ("raw", rnd.choice(WRONG + EXTREME + NAN_TOKENS[fmt]))
        refuse = name == "format_version"
    return f, f"{op}:{name}", refuse


def _isnum(x):
    try:
        float(x)
        return True
    except ValueError:
        return False


def byte_mutant(rnd, data):
    """A byte-level mutation of ``data``: (bytes, description)."""
    op = rnd.choice(
        [
            "truncate",
            "flip",
            "nonutf8",
            "insert",
            "delete_line",
            "dup_line",
            "zero",
            "shuffle_lines",
            "multi",
        ]
    )
    b = bytearray(data)
    if op == "truncate":
        b = b[: rnd.randrange(len(b))]
    elif op == "flip":
        for _ in range(rnd.randint(1, 8)):
            i = rnd.randrange(len(b))
            b[i] ^= 1 << rnd.randrange(8)
    elif op == "nonutf8":
        seq = rnd.choice([b"\xff", b"\xfe\xff", b"\xc3", b"\x80\x80", b"\xed\xa0\x80", b"\xc0\xaf"])
        if rnd.random() < 0.5 and b"misaligned_hyperbolic" in b:
            i = bytes(b).index(b"misaligned_hyperbolic") + rnd.randrange(21)
        else:
            i = rnd.randrange(len(b) + 1)
        b[i:i] = seq
    elif op == "insert":
        i = rnd.randrange(len(b) + 1)
        b[i:i] = rnd.choice(
            [
                b"{",
                b"[",
                b"<a>",
                b"- ",
                b":",
                b'"',
                b"\\",
                b"&x ",
                b"*x",
                b"!!binary",
                b"%YAML:1.0",
                b"\t",
                b"#",
                b"'",
                b"\r\n",
                b"\x0b",
            ]
        )
    elif op == "zero":
        i = rnd.randrange(len(b))
        b[i] = 0
    elif op in ("delete_line", "dup_line", "shuffle_lines"):
        lines = bytes(b).split(b"\n")
        i = rnd.randrange(len(lines))
        if op == "delete_line":
            del lines[i]
        elif op == "dup_line":
            lines.insert(i, lines[i])
        else:
            j = rnd.randrange(len(lines))
            lines[i], lines[j] = lines[j], lines[i]
        b = bytearray(b"\n".join(lines))
    else:
        for _ in range(3):
            b = bytearray(byte_mutant(rnd, bytes(b) or b" ")[0])
    return bytes(b), op


def deep_text(fmt, depth):
    if fmt == "json":
        return "[" * depth + "]" * depth
    if fmt == "xml":
        return (
            '<?xml version="1.0"?>\n<opencv_storage>\n'
            + "<a>" * depth
            + "1"
            + "</a>" * depth
            + "\n</opencv_storage>\n"
        )
    if fmt == "yaml_flow":
        return "%YAML:1.0\n---\nK: " + "[" * depth + "1" + "]" * depth + "\n"
    if fmt == "yaml_seq":
        return "%YAML:1.0\n---\nK:\n" + "- " * depth + "1\n"
    return "%YAML:1.0\n---\n" + "".join(" " * i + f"k{i}:\n" for i in range(depth)) + "\n"


# ==============================================================================================
# The worker: runs one case at a time, stdout/stderr captured at the fd level
# ==============================================================================================
class Captured:
    """fd 1 and fd 2 redirected into temporary files while a case runs."""

    def __enter__(self):
        sys.stdout.flush()
        sys.stderr.flush()
        self.files = [tempfile.TemporaryFile(), tempfile.TemporaryFile()]
        self.saved = [os.dup(1), os.dup(2)]
        os.dup2(self.files[0].fileno(), 1)
        os.dup2(self.files[1].fileno(), 2)
        return self

    def text(self, which):
        (sys.stdout if which == 0 else sys.stderr).flush()
        f = self.files[which]
        if f.closed:
            return self.final[which]
        f.seek(0)
        return f.read().decode("utf-8", "backslashreplace")

    def __exit__(self, *exc):
        sys.stdout.flush()
        sys.stderr.flush()
        for fd, saved in zip((1, 2), self.saved, strict=True):
            os.dup2(saved, fd)
            os.close(saved)
        self.final = [self.text(0), self.text(1)]
        for f in self.files:
            f.close()
        return False


def _temps(folder):
    with contextlib.suppress(OSError):
        return [n for n in os.listdir(folder) if TEMP_MARK in n]
    return []


def _names_ok(msg, names):
    return any(n in msg for n in names)


def _exc_outcome(e, names):
    """Classify an exception raised by the API."""
    msg = str(e)
    if not isinstance(e, ALLOWED):
        return "bad", f"wrong exception type {type(e).__name__}: {msg[:300]}"
    if not _names_ok(msg, names):
        return "bad", f"{type(e).__name__} names none of {names}: {msg[:300]}"
    return "ok", f"{type(e).__name__}: {msg[:120]}"


class Ctx:
    """Shared objects of the worker (built once)."""

    def __init__(self, workdir):
        import numpy as np

        import omnicam
        from omnicam import synthetic

        self.np = np
        self.omnicam = omnicam
        self.workdir = workdir
        self.cam = synthetic.misaligned_rig()
        self.cam_d = self.cam.replace(D=[-0.1, 0.02, 0.001, -0.001, 0.0])
        with open(os.path.join(workdir, "setup.json")) as f:
            self.setup = json.load(f)


def _check_loaded(ctx, cam, expect):
    """A loaded camera must be sane and hold what the file says."""
    np = ctx.np
    if not (np.isfinite(cam.R).all() and np.isfinite(cam.K).all()):
        return "bad", "loaded a camera with a non-finite R or K"
    if expect is not None:
        K = np.array(expect["K"], dtype=float).reshape(3, 3) if expect.get("K") else None
        if K is not None and not np.allclose(cam.K, K, rtol=1e-9, atol=0):
            return "bad", f"loaded K {cam.K.ravel().tolist()} differs from the file's {expect['K']}"
        if expect.get("tvec") and not np.allclose(
            cam.tvec, np.array(expect["tvec"], float), rtol=1e-9, atol=1e-12
        ):
            return "bad", f"loaded tvec differs from the file's {expect['tvec']}"
    from omnicam.cli.info import describe_camera

    describe_camera(cam)  # what `omnicam info` computes: must not blow up
    return "ok", "loaded"


def case_load(ctx, spec, cap):
    path = spec["path"]
    names = [os.path.basename(path), spec.get("shown", path)]
    try:
        if spec["what"] == "calibration":
            cam = ctx.omnicam.MisalignedHyperbolicCamera.load(path)
            if spec.get("refuse"):
                return "bad", f"accepted a file that must be refused ({spec.get('desc')})"
            return _check_loaded(ctx, cam, spec.get("expect"))
        if spec["what"] == "intrinsics":
            K, D, size = ctx.omnicam.read_intrinsics(path)
            if spec.get("refuse"):
                return "bad", f"accepted an intrinsics file that must be refused ({spec['desc']})"
            if not ctx.np.isfinite(K).all():
                return "bad", "non-finite K"
            return "ok", "read"
        lines = ctx.omnicam.read_far_lines(path)
        if not all(ctx.np.isfinite(x).all() and x.shape[1] == 2 for x in lines):
            return "bad", "far lines not finite (N, 2)"
        return "ok", "read"
    except Exception as e:
        out = _exc_outcome(e, [n for n in names if n])
        if spec.get("must_load"):
            return "bad", f"refused a file OpenCV reads ({spec.get('desc')}): {str(e)[:200]}"
        missing = [w for w in spec.get("must_name", ()) if w not in str(e)]
        if out[0] == "ok" and missing:
            return "bad", f"the message does not name {missing}: {str(e)[:200]}"
        if spec.get("missing") and out[0] == "ok" and not isinstance(e, FileNotFoundError):
            return "bad", f"a missing file gave {type(e).__name__}, not FileNotFoundError"
        if spec.get("not_regular") and "not a regular file" not in str(e):
            return "bad", f"a {spec['not_regular']} named *.yaml: {str(e)[:200]}"
        return out


def case_cli(ctx, spec, cap):
    from omnicam.cli import main

    rc = main(spec["argv"])
    return _cli_outcome(rc, cap.text(1), spec)


def _without_notices(err):
    """stderr without omnicam's own one-time notices (the first compilation of its kernels, a
    cache folder that cannot be written): they are meant for the user, once per process."""
    return "\n".join(
        ln
        for ln in err.replace("\r", "\n").splitlines()
        if not ln.startswith(("omnicam: compiling kernels", "omnicam: numba cannot write"))
    )


def _cli_outcome(rc, err, spec):
    lines = [ln for ln in _without_notices(err).splitlines() if ln.strip()]
    lines = [ln for ln in lines if not re.match(r"^\[[#.]*\] \d+|^\d+ frames", ln.strip())]
    allowed = spec.get("rc", (0, 1, 2))
    if rc not in allowed:
        return "bad", f"exit status {rc} (expected one of {allowed}); stderr {lines[-3:]}"
    errors = [ln for ln in lines if ln.startswith("omnicam: error:")]
    other = [ln for ln in lines if not ln.startswith(("omnicam: error:", "omnicam: warning:"))]
    if other:
        return "bad", f"stray stderr lines beside omnicam's: {other[:3]}"
    if rc != 0 and len(errors) != 1:
        return "bad", f"exit {rc} with {len(errors)} error lines: {lines[:3]}"
    if any("unexpected" in ln for ln in errors):
        return "bad", f"an unexpected error: {errors[0][:300]}"
    for name in spec.get("must_name", ()):
        if rc != 0 and name not in errors[0]:
            return "bad", f"the error does not name {name}: {errors[0][:200]}"
    return "ok", f"rc {rc}: {(errors or lines or [''])[0][:100]}"


def case_api(ctx, spec, cap):
    label, names, fn = API_CASES[spec["index"]]
    try:
        result = fn(ctx)
    except Exception as e:
        return _exc_outcome(e, names)
    if (
        isinstance(result, tuple)
        and len(result) == 2
        and isinstance(result[0], str)
        and result[0] == "__must_raise__"
    ):
        return "bad", f"accepted: {result[1]}"
    return "ok", "returned"


def _snapshot(path):
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError:
        return None


def case_save(ctx, spec, cap):
    """Save over an existing file; a failure must keep it, success must read back."""
    path = spec["path"]
    folder = os.path.dirname(path)
    before = _snapshot(path)
    kind = spec["writer"]
    om = ctx.omnicam
    if spec.get("loads_first"):  # after a killed writer: the file must be whole
        try:
            om.MisalignedHyperbolicCamera.load(path)
        except Exception as e:
            return "bad", f"the file left by a killed save does not load: {e}"
    try:
        if kind == "camera":
            ctx.cam_d.save(path)
        elif kind == "intrinsics":
            om.write_intrinsics(path, ctx.cam.K, ctx.cam_d.D, ctx.cam.image_size)
        elif kind == "far_lines":
            om.write_far_lines(path, [ctx.np.arange(8.0).reshape(4, 2) + i for i in range(3)])
        else:
            raise AssertionError(kind)
        failed = None
    except Exception as e:
        failed = e
    left = _temps(folder)
    if left:
        return "bad", f"temporary files left: {left}"
    if failed is not None:
        if _snapshot(path) != before:
            return "bad", f"a failed save changed the old file ({type(failed).__name__})"
        base = os.path.basename(path)
        out = _exc_outcome(
            failed,
            [base, base.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")],
        )
        if out[0] == "ok" and spec.get("must_succeed"):
            return "bad", f"save failed: {failed}"
        return out
    if spec.get("must_fail"):
        return "bad", f"save returned normally although it cannot succeed ({spec['desc']})"
    if kind == "camera" and om.MisalignedHyperbolicCamera.load(path) != ctx.cam_d:
        return "bad", "the saved file does not read back equal"
    return "ok", "saved"


def case_cli_write(ctx, spec, cap):
    """A CLI command writing over existing outputs on a full / read-only disk."""
    from omnicam.cli import main

    before = {p: _snapshot(p) for p in spec["keep"]}
    rc = main(spec["argv"])
    out = _cli_outcome(rc, cap.text(1), spec)
    if out[0] == "bad":
        return out
    for p, b in before.items():
        if rc != 0 and _snapshot(p) != b:
            return "bad", f"exit {rc} but {os.path.basename(p)} was changed or lost"
        if rc == 0 and spec.get("must_fail"):
            now = _snapshot(p) or b""
            fate = "unchanged" if now == b else f"replaced by {len(now)} bytes"
            return "bad", (
                f"exit 0 and 'wrote' on a full/read-only disk: {os.path.basename(p)} "
                f"{fate}; stdout {cap.text(0).strip()[-80:]!r}"
            )
    left = _temps(os.path.dirname(spec["keep"][0]))
    if left:
        return "bad", f"temporary files left: {left}"
    return out


KINDS = {
    "load": case_load,
    "cli": case_cli,
    "api": case_api,
    "save": case_save,
    "cli_write": case_cli_write,
}


def worker_main(workdir, as_user=None):
    import faulthandler

    faulthandler.enable(file=sys.__stderr__, all_threads=False)
    out = os.fdopen(os.dup(1), "w", buffering=1)
    ctx = Ctx(workdir)
    if as_user is not None:  # drop to another user once everything is imported
        import omnicam.cli
        import omnicam.cli.info

        omnicam.MisalignedHyperbolicCamera.load(ctx.setup["calib"]).best_fit_viewpoint()
        os.setegid(as_user)
        os.seteuid(as_user)
    out.write(json.dumps({"ready": True}) + "\n")
    for line in sys.stdin:
        spec = json.loads(line)
        t0 = time.perf_counter()
        with Captured() as cap:
            try:
                status, detail = KINDS[spec["kind"]](ctx, spec, cap)
            except Exception as e:
                status = "bad"
                detail = f"uncaught {type(e).__name__}: {str(e)[:300]} | " + " / ".join(
                    traceback.format_exc().splitlines()[-4:-1]
                )
            err = _without_notices(cap.text(1))
        if status == "ok" and spec["kind"] not in ("cli", "cli_write") and err.strip():
            status, detail = "bad", f"stderr output during the call: {err.strip()[:300]!r}"
        out.write(
            json.dumps(
                {"status": status, "detail": detail, "seconds": round(time.perf_counter() - t0, 3)}
            )
            + "\n"
        )


# ==============================================================================================
# API cases: built in the worker from an index (the same list in runner and worker)
# ==============================================================================================
BAD_NUMBERS = [
    "a",
    None,
    [1.0],
    1j,
    float("nan"),
    float("inf"),
    -float("inf"),
    0,
    -1,
    1e-300,
    1e300,
    True,
    "1e3",
    (),
    {},
    10**400,
]
BAD_ARRAYS = [
    "abc",
    None,
    1j,
    [1, 2],
    [[1, 2], [3]],
    [1j, 0, 0],
    "nan",
    [float("nan")] * 3,
    [1e300, 0, 0],
    [True, False, True],
    [None, 1, 2],
    [[1.0] * 3] * 4,
    {},
    5,
    [10**400, 0, 0],
]
BAD_SIZES = [
    (float("inf"), 500),
    ("ab", 5),
    "ab",
    (0, 5),
    (1e6, 1e6),
    (1.5, 2),
    True,
    (640,),
    (-1, 5),
    (640, 480, 3),
    1j,
    (1j, 2),
    (2**40, 1),
    None,
    (640.0, float("nan")),
    ([1], [2]),
]
BAD_IMAGES = [
    None,
    "img",
    [[1, 2], [3, 4]],
    "bool",
    "empty",
    "1x1",
    "nan",
    "4ch",
    "complex",
    "3d5",
    7,
    "obj",
]


def _image(ctx, tag):
    np = ctx.np
    if not isinstance(tag, str):
        return tag
    return {
        "bool": np.ones((64, 64), bool),
        "empty": np.zeros((0, 0), np.uint8),
        "1x1": np.zeros((1, 1), np.uint8),
        "nan": np.full((64, 64), np.nan),
        "4ch": np.zeros((64, 64, 4), np.uint8),
        "complex": np.zeros((64, 64), complex),
        "3d5": np.zeros((64, 64, 5), np.uint8),
        "obj": np.zeros((64, 64), object),
        "img": "img",
    }.get(tag, tag)


def _api_cases():
    cases = []

    def add(label, names, fn):
        cases.append((label, names, fn))

    def must_raise(what):
        return ("__must_raise__", what)

    from_mirror = ("a", "b", "rim_radius")
    for i, pname in enumerate(from_mirror):
        for v in BAD_NUMBERS + [2e6, 1e-4]:

            def fn(ctx, i=i, v=v, pname=pname):
                args = [28.0, 23.0, 30.0]
                args[i] = v
                ctx.omnicam.HyperbolicMirror(*args)
                return must_raise(f"{pname}={v!r}")

            add(f"HyperbolicMirror({pname}={v!r})", [pname], fn)

    def cam_with(ctx, **kw):
        c = ctx.cam
        args = dict(
            K=c.K, mirror=c.mirror, rvec=c.rvec, tvec=c.tvec, D=None, image_size=c.image_size
        )
        args.update(kw)
        return ctx.omnicam.MisalignedHyperbolicCamera(**args)

    for pname, pool in (
        ("K", BAD_ARRAYS + ["fx1e12", "fx0", "fxneg", "fy1e-9", "Kc", "Kbool"]),
        ("rvec", BAD_ARRAYS + ["pi", "big"]),
        ("tvec", BAD_ARRAYS + ["behind", "upper", "far"]),
        (
            "D",
            [v for v in BAD_ARRAYS if v is not None and not (isinstance(v, list) and len(v) == 4)]
            + ["D3", "Dhuge"],
        ),
        ("image_size", [v for v in BAD_SIZES if v is not None]),
        ("mirror", [None, "m", 5, (28, 23, 30)]),
    ):
        for v in pool:

            def fn(ctx, pname=pname, v=v):
                np = ctx.np
                K = ctx.cam.K
                special = {
                    "fx1e12": np.array([[1e12, 0, 250], [0, 1e12, 250], [0, 0, 1]]),
                    "fx0": np.array([[0.0, 0, 250], [0, 300, 250], [0, 0, 1]]),
                    "fxneg": K * np.array([[-1, 1, 1], [1, 1, 1], [1, 1, 1]]),
                    "fy1e-9": np.array([[300, 0, 250], [0, 1e-9, 250], [0, 0, 1.0]]),
                    "Kc": K.astype(complex) + 1j,
                    "Kbool": np.eye(3, dtype=bool),
                    "pi": [math.pi, 0, 0],
                    "big": [1e300, 0, 0],
                    "behind": [0, 0, -100.0],
                    "upper": [0, 0, -ctx.cam.mirror.c],
                    "far": [0, 0, 1e12],
                    "D3": [0.1, 0.2, 0.3],
                    "Dhuge": [1e300, 0, 0, 0, 0],
                }
                value = special.get(v, v) if isinstance(v, str) else v
                cam_with(ctx, **{pname: value})
                return must_raise(f"{pname}={v!r}")

            add(
                f"Camera({pname}={v!r})",
                [pname]
                + (["fx", "fy", "K"] if pname == "K" else [])
                + (["rvec", "tvec"] if pname in ("rvec", "tvec") else []),
                fn,
            )

    pts_pool = [
        None,
        "abc",
        1j,
        [1, 2, 3],
        [[1, 2, 3, 4]],
        "cplx",
        "obj",
        "empty",
        "huge",
        "nanrows",
        [[1e300, 1e300]],
        "f32",
        "n11",
        [[True, False]],
    ]
    for meth, dim in (("unproject", 2), ("project", 3), ("project_directions", 3)):
        for v in pts_pool:

            def fn(ctx, meth=meth, dim=dim, v=v):
                np = ctx.np
                special = {
                    "cplx": np.ones((4, dim), complex),
                    "obj": np.ones((4, dim), object),
                    "empty": np.zeros((0, dim)),
                    "huge": np.full((4, dim), 1e300),
                    "nanrows": np.full((4, dim), np.nan),
                    "f32": np.ones((4, dim), np.float32) * 100,
                    "n11": np.ones((4, 1, dim)) * 100,
                }
                value = special.get(v, v) if isinstance(v, str) else v
                if (
                    isinstance(value, list)
                    and value
                    and isinstance(value[0], list)
                    and len(value[0]) != dim
                ):
                    value = [row[:dim] + [0.0] * (dim - len(row)) for row in value]
                return getattr(ctx.cam, meth)(value)

            add(f"{meth}({v!r})", ["image_points", "object_points", "directions", "points"], fn)
    for kw in (
        {"rvec": [1j, 0, 0], "tvec": [0, 0, 0]},
        {"rvec": [0, 0, 0]},
        {"rvec": "a", "tvec": [0, 0, 0]},
        {"rvec": [0, 0, 0], "tvec": [float("inf")] * 3},
    ):
        add(
            f"project(rvec/tvec {kw})",
            ["rvec", "tvec"],
            lambda ctx, kw=kw: ctx.cam.project(ctx.np.ones((2, 3)) * 1000, **kw),
        )

    for v in BAD_SIZES:
        add(f"scaled({v!r})", ["image_size"], lambda ctx, v=v: ctx.cam.scaled(v))
    for n in ["a", -1, 0, 1e12, float("inf"), 2.5, None]:
        add(f"rim_image_points({n!r})", ["n"], lambda ctx, n=n: ctx.cam.rim_image_points(n))
    add("replace(bogus=1)", ["bogus"], lambda ctx: ctx.cam.replace(bogus=1))

    views_args = {
        "size": BAD_SIZES + [(40000, 10)],
        "elevation_range": ["a", (10, -10), (float("inf"), 0), (1j, 2), (-95, 0), (0,), None],
        "projection": ["bogus", None, 5, ["cylindrical"]],
        "R": BAD_ARRAYS + ["notrot"],
        "m1type": ["a", 1.5, 99, None, True],
        "depth": ["a", -1, 0, float("inf"), 1j, float("nan"), "5"],
        "viewpoint": ["a", [1, 2], [1j, 0, 0], [float("nan")] * 3],
    }
    for fname in ("init_panorama_maps", "init_perspective_maps"):
        for pname, pool in views_args.items():
            if fname == "init_perspective_maps" and pname in ("elevation_range", "projection"):
                continue
            for v in pool:

                def fn(ctx, fname=fname, pname=pname, v=v):
                    np = ctx.np
                    kw = {"size": (64, 32)}
                    if fname == "init_perspective_maps":
                        kw["K_new"] = np.array([[30.0, 0, 31.5], [0, 30, 15.5], [0, 0, 1]])
                    value = (
                        {"notrot": np.diag([1.0, 1.0, -1.0])}.get(v, v) if isinstance(v, str) else v
                    )
                    kw[pname] = value
                    if pname == "viewpoint":
                        kw["depth"] = 1000.0
                    return getattr(ctx.cam, fname)(**kw)

                add(f"{fname}({pname}={v!r})", [pname], fn)
        if fname == "init_perspective_maps":
            for v in BAD_ARRAYS + ["fx1e12"]:

                def fn(ctx, v=v):
                    value = ctx.np.diag([1e12, 1e12, 1.0]) if v == "fx1e12" else v
                    return ctx.cam.init_perspective_maps(value, (64, 32))

                add(f"init_perspective_maps(K_new={v!r})", ["K_new", "K"], fn)
    for v in BAD_NUMBERS:
        add(
            f"rotation_from_ypr(yaw={v!r})",
            ["yaw"],
            lambda ctx, v=v: __import__("omnicam.views").views.rotation_from_ypr(yaw=v),
        )
        add(
            f"K_from_fov({v!r})",
            ["fov_deg"],
            lambda ctx, v=v: __import__("omnicam.views").views.K_from_fov(v, (64, 32)),
        )
    for v in BAD_SIZES[:8]:
        add(f"PanoramaView({v!r})", ["size"], lambda ctx, v=v: ctx.omnicam.PanoramaView(v))
        add(f"PerspectiveView({v!r})", ["size"], lambda ctx, v=v: ctx.omnicam.PerspectiveView(v))
    for v in [None, "cam", 5]:
        add(
            f"visible_elevation_range({v!r})",
            ["camera"],
            lambda ctx, v=v: ctx.omnicam.visible_elevation_range(v),
        )

    for v in BAD_IMAGES:
        add(
            f"detect_rim(image={v!r})",
            ["image"],
            lambda ctx, v=v: ctx.omnicam.detect_rim(_image(ctx, v)),
        )
    for pname, pool in (
        ("sigma", ["a", 1e6, 1e5, -1, float("nan"), 1j, None, True, [1]]),
        ("threshold", ["a", 0, -1, float("inf"), 1j, None]),
        ("rng", ["abc", -1, 1.5, [1, 2], object()]),
    ):
        for v in pool:

            def fn(ctx, pname=pname, v=v):
                img = ctx.np.zeros((96, 96), ctx.np.uint8)
                import cv2

                cv2.circle(img, (48, 48), 35, 200, -1)
                return ctx.omnicam.detect_rim(img, **{pname: v})

            add(f"detect_rim({pname}={v!r})", [pname], fn)

    def calib_kw(ctx):
        c = ctx.cam
        return dict(
            K=c.K,
            mirror=c.mirror,
            boundary_points=c.rim_image_points(200),
            image_size=c.image_size,
            refine=False,
        )

    for pname, pool in (
        (
            "far_lines",
            [
                5,
                "abc",
                [[1, 2]],
                [[[1j, 0]] * 3],
                [[[float("nan"), 0]] * 3],
                [None],
                [[[1, 2]] * 2],
            ],
        ),
        ("boundary_points", ["abc", 1j, [[1j, 2]] * 10, [[1, 2]], None]),
        ("K", ["abc", 1j, None]),
        ("mirror", [None, "m"]),
        ("image_size", BAD_SIZES[:6]),
        ("D", ["abc", [1j] * 5]),
        ("lens", ["bogus", 5]),
    ):
        for v in pool:

            def fn(ctx, pname=pname, v=v):
                from omnicam import MisalignedHyperbolicCamera

                calibrate = MisalignedHyperbolicCamera.calibrate
                kw = calib_kw(ctx)
                kw[pname] = v
                return calibrate(**kw)

            add(f"calibrate({pname}={v!r})", [pname], fn)

    def unwarper(ctx, **kw):
        from omnicam import PanoramaView, Unwarper

        return Unwarper.from_camera(ctx.cam, {"p": PanoramaView((64, 32))}, **kw)

    for v in BAD_IMAGES + ["wrongsize", "bool@size", "int32@size", "float16@size", "int8@size"]:

        def fn(ctx, v=v):
            u = unwarper(ctx)
            if isinstance(v, str) and v.endswith("@size"):  # the right size, a dtype remap refuses
                w, h = u.source_size
                img = ctx.np.zeros((h, w), v.split("@")[0])
            elif v == "wrongsize":
                img = ctx.np.zeros((10, 10, 3), ctx.np.uint8)
            else:
                img = _image(ctx, v)
            return u.unwarp(img)

        add(f"Unwarper.unwarp({v!r})", ["frame", "image"], fn)
    for pname, pool in (
        ("frame_size", ["ab", (float("inf"), 5), (0, 5), 1j]),
        ("border_value", ["red", None, [1j], "0"]),
        ("interpolation", ["a", 99]),
        ("m1type", ["a", 7]),
    ):
        for v in pool:
            add(
                f"Unwarper.from_camera({pname}={v!r})",
                [pname],
                lambda ctx, pname=pname, v=v: unwarper(ctx, **{pname: v}),
            )

    for fname, pnames in (("save", ["path"]), ("load", ["path"])):
        for v in [
            None,
            5,
            3.5,
            b"\xff.yaml",
            "",
            "x.txt",
            "/",
            "/nonexistent/dir/c.yaml",
            "/dev/null",
            "\udcff.yaml",
            "a\x00b.yaml",
            ["c.yaml"],
        ]:

            def fn(ctx, fname=fname, v=v):
                if (
                    isinstance(v, (str, bytes))
                    and v not in ("", "/", "/dev/null")
                    and not str(v).startswith("/")
                ):
                    v = os.path.join(
                        ctx.workdir, "api", v.decode("latin-1") if isinstance(v, bytes) else v
                    )
                if fname == "save":
                    return ctx.cam.save(v)
                return ctx.omnicam.MisalignedHyperbolicCamera.load(v)

            add(f"{fname}({v!r})", pnames + [str(v), "file", "calibration"], fn)
    for pname, pool in (
        ("K", BAD_ARRAYS[:8]),
        ("D", ["abc", [1j] * 5, [1, 2]]),
        ("image_size", BAD_SIZES[:8]),
    ):
        for v in pool:

            def fn(ctx, pname=pname, v=v):
                kw = dict(K=ctx.cam.K, D=None, image_size=None)
                kw[pname] = v
                return ctx.omnicam.write_intrinsics(
                    os.path.join(ctx.workdir, "api", "k.yaml"), **kw
                )

            add(f"write_intrinsics({pname}={v!r})", [pname], fn)
    for v in [
        5,
        "abc",
        [[1, 2]],
        [[[1j, 0]] * 3],
        [[[float("nan"), 0]] * 3],
        None,
        [],
        [[[1, 2, 3]] * 3],
        [[[10**400, 0]] * 3],
    ]:
        add(
            f"write_far_lines({v!r})",
            ["far_lines"],
            lambda ctx, v=v: ctx.omnicam.write_far_lines(
                os.path.join(ctx.workdir, "api", "f.json"), v
            ),
        )
    for fname in ("read_intrinsics", "read_far_lines"):
        for v in [None, 5, "/nonexistent.yaml", "/dev/null", "/", "\udcff.json"]:
            add(
                f"{fname}({v!r})",
                ["path", str(v), "file"],
                lambda ctx, fname=fname, v=v: getattr(ctx.omnicam, fname)(v),
            )
    _complex_cases(add)
    return cases


def _complex_cases(add):
    """Issue 18 item 8: complex values whose imaginary part is 0, which numpy's casts and
    ``float()`` would cut to their real part with only a ComplexWarning (stderr: bad)."""

    def cplx(np, value):
        return np.asarray(value, dtype=float).astype(complex)

    def cal(ctx, **kw):
        c = ctx.cam
        args = dict(
            K=c.K,
            mirror=c.mirror,
            boundary_points=c.rim_image_points(60),
            image_size=c.image_size,
            refine=False,
        )
        args.update(kw)
        return ctx.omnicam.MisalignedHyperbolicCamera.calibrate(**args)

    p3 = [[10.0, 5.0, 30.0], [0.0, 2.0, 31.0]]
    for label, names, fn in (
        (
            "calibrate(boundary_points)",
            ["boundary_points"],
            lambda ctx: cal(ctx, boundary_points=cplx(ctx.np, ctx.cam.rim_image_points(60))),
        ),
        (
            "calibrate(rim_hint)",
            ["rim_hint"],
            lambda ctx: cal(
                ctx,
                boundary_points=None,
                image=ctx.np.zeros((64, 64), ctx.np.uint8),
                image_size=None,
                rim_hint=cplx(ctx.np, [32, 32, 20]),
            ),
        ),
        (
            "calibrate(max_tilt_deg)",
            ["max_tilt_deg"],
            lambda ctx: cal(ctx, max_tilt_deg=ctx.np.complex128(10)),
        ),
        ("mirror.normal", ["points"], lambda ctx: ctx.cam.mirror.normal(cplx(ctx.np, p3))),
        (
            "mirror.intersect",
            ["origins"],
            lambda ctx: ctx.cam.mirror.intersect(cplx(ctx.np, p3), p3),
        ),
        (
            "mirror.reflect",
            ["directions"],
            lambda ctx: ctx.cam.mirror.reflect(cplx(ctx.np, p3), p3),
        ),
        (
            "mirror.surface_z",
            ["X"],
            lambda ctx: ctx.cam.mirror.surface_z(cplx(ctx.np, [1.0]), [2.0]),
        ),
        (
            "rotation_from_ypr",
            ["yaw"],
            lambda ctx: __import__("omnicam.views").views.rotation_from_ypr(
                yaw=ctx.np.complex128(10)
            ),
        ),
        (
            "K_from_fov",
            ["fov_deg"],
            lambda ctx: __import__("omnicam.views").views.K_from_fov(
                ctx.np.complex128(60), (64, 32)
            ),
        ),
        (
            "scale_K",
            ["K"],
            lambda ctx: __import__("omnicam.camera").camera.scale_K(
                cplx(ctx.np, ctx.cam.K), (500, 500), (250, 250)
            ),
        ),
    ):
        add(f"item8: complex {label}", names, fn)


API_CASES = _api_cases()


# ==============================================================================================
# The runner
# ==============================================================================================
class Worker:
    def __init__(self, workdir, user=None):
        self.workdir, self.user = workdir, user
        self.proc = None

    def start(self):
        env = dict(os.environ, PYTHONPATH=REPO, PYTHONWARNINGS="default")
        env.pop("OMNICAM_DEBUG", None)
        extra = [] if self.user is None else ["--as-user", str(self.user)]
        self.log = open(os.path.join(self.workdir, f"worker-{self.user}.log"), "ab")
        self.proc = subprocess.Popen(
            [sys.executable, os.path.abspath(__file__), "--worker", self.workdir, *extra],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self.log,
            env=env,
            cwd=self.workdir,
        )
        line = self._readline(300)
        if not line:
            raise RuntimeError(f"the fuzz worker did not start: {self._log_tail()}")

    def _readline(self, timeout):
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        if not ready:
            return None
        return self.proc.stdout.readline()

    def _log_tail(self):
        self.log.flush()
        with open(self.log.name, "rb") as f:
            data = f.read()[-600:]
        return data.decode("utf-8", "replace").strip().replace("\n", " | ")

    def run(self, spec, timeout):
        if self.proc is None or self.proc.poll() is not None:
            self.start()
        self.proc.stdin.write((json.dumps(spec) + "\n").encode())
        self.proc.stdin.flush()
        line = self._readline(timeout)
        if line:
            return json.loads(line)
        if line is None:  # timeout
            self.kill()
            return {"status": "bad", "detail": f"hang: no answer in {timeout:g} s"}
        rc = self.proc.wait()
        self.proc = None
        sig = -rc if rc < 0 else None
        name = signal.Signals(sig).name if sig else f"exit {rc}"
        return {"status": "bad", "detail": f"crash ({name}): {self._log_tail()[-300:]}"}

    def kill(self):
        if self.proc is not None:
            with contextlib.suppress(OSError):
                self.proc.kill()
            self.proc.wait()
            self.proc = None

    def close(self):
        if self.proc is not None and self.proc.poll() is None:
            self.proc.stdin.close()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.kill()
        self.proc = None


class Runner:
    def __init__(self, args):
        self.args = args
        self.rnd = random.Random(args.seed)
        self.workdir = tempfile.mkdtemp(prefix="omnicam-fuzz-")
        self.counts = collections.defaultdict(collections.Counter)
        self.bad = []
        self.skipped = []
        self.worker = Worker(self.workdir)
        self.mounts = []
        self.n = 0

    # -- bookkeeping -----------------------------------------------------------------------
    def record(self, category, label, result):
        status = result["status"]
        self.counts[category][status] += 1
        self.n += 1
        if status == "bad":
            self.bad.append((category, label, result["detail"]))
            if self.args.verbose:
                print(f"  BAD {category}: {label}: {result['detail']}", flush=True)

    def run(self, category, label, spec, timeout=None, worker=None):
        result = (worker or self.worker).run(spec, timeout or self.args.timeout)
        if self.args.verbose and result.get("seconds", 0) > 2:
            print(f"  slow ({result['seconds']:.1f} s) {category}: {label}", flush=True)
        self.record(category, label, result)
        return result

    def path(self, *parts):
        p = os.path.join(self.workdir, *parts)
        os.makedirs(os.path.dirname(p), exist_ok=True)
        return p

    # -- setup: good files, images, videos (in this process, with omnicam) -------------------
    def setup(self):
        import cv2
        import numpy as np

        from omnicam import synthetic, write_far_lines, write_intrinsics

        cam = synthetic.misaligned_rig()
        self.cam = cam
        self.cam_d = cam.replace(D=[-0.1, 0.02, 0.001, -0.001, 0.0])
        os.makedirs(self.path("api", "x"), exist_ok=True)
        self.good = {}
        for fmt in ("yaml", "xml", "json"):
            for c, tag in ((cam, ""), (self.cam_d, "_d")):
                text = render(base_fields(c), fmt)
                p = self.path("good", f"calib{tag}.{fmt}")
                with open(p, "w") as f:
                    f.write(text)
                self.good[(fmt, tag)] = p
        write_intrinsics(self.path("good", "k.yaml"), cam.K, None, cam.image_size)
        write_far_lines(
            self.path("good", "lines.json"),
            [np.array([[10.0 * i + j, 5.0 * j] for j in range(5)]) for i in range(3)],
        )
        image = synthetic.render_environment(cam, supersample=1, seed=1)
        self.image = self.path("good", "mirror.png")
        cv2.imwrite(self.image, image)
        cv2.imwrite(self.path("good", "mirror.jpg"), image)
        cv2.imwrite(self.path("good", "mirror.tif"), image)
        small = cv2.resize(image, (250, 250), interpolation=cv2.INTER_AREA)
        self.video = self.path("good", "clip.avi")
        vw = cv2.VideoWriter(self.video, cv2.VideoWriter_fourcc(*"MJPG"), 25, (250, 250))
        for i in range(40):
            vw.write(np.roll(small, i, axis=1))
        vw.release()
        self.long_video = self.path("good", "long.avi")
        vw = cv2.VideoWriter(self.long_video, cv2.VideoWriter_fourcc(*"MJPG"), 25, (500, 500))
        for i in range(400):
            vw.write(np.roll(image, i, axis=1))
        vw.release()
        self.calib = self.good[("yaml", "")]
        with open(self.path("setup.json"), "w") as f:
            json.dump({"calib": self.calib}, f)

    # -- categories ------------------------------------------------------------------------
    def file_mutants(self, n_sem, n_byte, info_every):
        """Calibration-file mutants in yaml, yml, xml, json: load() and `omnicam info`."""
        import numpy as np

        rnd = self.rnd
        exts = {"yaml": [".yaml", ".yml"], "xml": [".xml"], "json": [".json"]}
        count = 0
        for i in range(n_sem + n_byte):
            fmt = rnd.choice(["yaml", "xml", "json"])
            ext = rnd.choice(exts[fmt])
            cam = rnd.choice([self.cam, self.cam_d])
            fields = base_fields(cam)
            expect = None
            if i < n_sem:
                fields, desc, refuse = semantic_mutant(rnd, fields, fmt)
                data = render(fields, fmt).encode()
                if (
                    "K" in fields
                    and fields["K"][0] == "mat"
                    and fields["K"][3] in "uwcs"
                    and len(fields["K"][4]) == 9
                    and all(_isnum(x) for x in fields["K"][4])
                ):
                    expect = {"K": [float(x) for x in fields["K"][4]]}
                cat = f"calibration file ({fmt}, field mutants)"
            else:
                data, desc = byte_mutant(rnd, render(fields, fmt).encode())
                refuse = False
                cat = f"calibration file ({fmt}, byte mutants)"
            p = self.path("mut", fmt, f"m{i}{ext}")
            with open(p, "wb") as f:
                f.write(data)
            label = f"{desc} -> {os.path.basename(p)}"
            self.run(
                cat,
                label,
                {
                    "kind": "load",
                    "what": "calibration",
                    "path": p,
                    "refuse": refuse,
                    "desc": desc,
                    "expect": expect,
                },
            )
            if info_every and count % info_every == 0:
                self.run(
                    "omnicam info on mutants",
                    label,
                    {"kind": "cli", "argv": ["info", p], "must_name": [os.path.basename(p)]},
                )
            count += 1
        del np

    def intrinsics_mutants(self, n):
        rnd = self.rnd
        import numpy as np

        for i in range(n):
            fmt = rnd.choice(["yaml", "xml", "json"])
            K = self.cam.K
            style = rnd.choice(["omnicam", "sample"])
            if style == "omnicam":
                fields = {
                    "K": ("mat", 3, 3, "d", [_num(v) for v in K.ravel()]),
                    "D": ("mat", 1, 5, "d", ["-0.1", "0.02", "0.", "0.", "0."]),
                    "image_size": ("seq", ["500", "500"]),
                }
            else:
                fields = {
                    "image_width": ("raw", "500"),
                    "image_height": ("raw", "500"),
                    "camera_matrix": ("mat", 3, 3, "d", [_num(v) for v in K.ravel()]),
                    "distortion_coefficients": ("mat", 5, 1, "d", ["0.1"] + ["0."] * 4),
                }
            if rnd.random() < 0.5:
                fields, desc, refuse = semantic_mutant(rnd, fields, fmt)
                data = render(fields, fmt).encode()
                refuse = (
                    refuse
                    and desc.split(":")[0] not in ("model", "posture")
                    and desc.split(":")[1] in ("K", "camera_matrix")
                )
            else:
                data, desc = byte_mutant(rnd, render(fields, fmt).encode())
                refuse = False
            p = self.path("intr", f"k{i}.{fmt}")
            with open(p, "wb") as f:
                f.write(data)
            self.run(
                f"intrinsics file ({fmt})",
                f"{desc} -> {os.path.basename(p)}",
                {"kind": "load", "what": "intrinsics", "path": p, "refuse": refuse, "desc": desc},
            )
        del np

    def far_line_mutants(self, n):
        rnd = self.rnd
        with open(self.path("good", "lines.json"), "rb") as f:
            good = f.read()
        variants = [
            "[]",
            "{}",
            "5",
            '"abc"',
            "[[[1,2],[3,4]]]",
            "[[[1,2],[3,4],[5]]]",
            "[[[1,2],[3,4],[5,NaN]]]",
            "[[[1,2],[3,4],[5,Infinity]]]",
            "[[[1,2],[3,4],[5,1e400]]]",
            "[[[1,2],[3,4],[5,true]]]",
            '[[[1,2],[3,4],[5,"6"]]]',
            "[[[1,2],[3,4],[5,null]]]",
            "[[[1,2],[3,4],[5," + "9" * 400 + "]]]",
            '[[{"x":1}]*3]',
            "null",
        ]
        for i in range(n):
            if i < len(variants):
                data, desc = variants[i].encode(), f"shape:{variants[i][:30]}"
            else:
                data, desc = byte_mutant(rnd, good)
            p = self.path("lines", f"l{i}.json")
            with open(p, "wb") as f:
                f.write(data)
            self.run(
                "far-lines file",
                f"{desc} -> {os.path.basename(p)}",
                {"kind": "load", "what": "far_lines", "path": p},
            )

    def special_files(self):
        """Directories, FIFOs, devices, non-UTF-8 names, empty, binary, huge, deep nesting."""
        d = self.path("special", "x")
        d = os.path.dirname(d)
        cases = []
        os.makedirs(os.path.join(d, "folder.yaml"), exist_ok=True)
        cases.append(("folder.yaml", "a folder", {"not_regular": "folder"}))
        fifo = os.path.join(d, "fifo.yaml")
        if not os.path.exists(fifo):
            os.mkfifo(fifo)
        cases.append(("fifo.yaml", "a FIFO", {"not_regular": "FIFO"}))
        with contextlib.suppress(FileExistsError):
            os.symlink("/dev/null", os.path.join(d, "null.yaml"))
        cases.append(("null.yaml", "a link to /dev/null", {"not_regular": "device"}))
        with contextlib.suppress(FileExistsError):
            os.symlink("/dev/zero", os.path.join(d, "zero.json"))
        cases.append(("zero.json", "a link to /dev/zero", {"not_regular": "device"}))
        with contextlib.suppress(FileExistsError):
            os.symlink(os.path.join(d, "nowhere.yaml"), os.path.join(d, "dangling.yaml"))
        cases.append(("dangling.yaml", "a dangling link", {"missing": True}))
        cases.append(("missing.yaml", "a missing file", {"missing": True}))
        files = {
            "empty.yaml": b"",
            "empty.json": b"",
            "empty.xml": b"",
            "spaces.yaml": b"   \n\n",
            "binary.yaml": bytes(range(256)) * 8,
            "binary.json": os.urandom(2048),
            "png.xml": b"\x89PNG\r\n\x1a\n" + os.urandom(200),
            "nul.yaml": b"%YAML:1.0\n\0\0",
            "bom.json": b"\xef\xbb\xbf{}",
            "huge.yaml": b"%YAML:1.0\n#" + b"x" * (2 << 20),
            "deep.json": deep_text("json", 100000).encode(),
            "deep.xml": deep_text("xml", 30000).encode(),
            "deepflow.yaml": deep_text("yaml_flow", 100000).encode(),
            "deepseq.yaml": deep_text("yaml_seq", 20000).encode(),
            "deepmap.yaml": deep_text("yaml_map", 3000).encode(),
            "deep40.json": deep_text("json", 40).encode(),
            "base64.yaml": b'%YAML:1.0\n---\nK: [ "$base64$AAAAAAAA" ]\n',
            "model_ff.json": render(base_fields(self.cam), "json")
            .replace("misaligned_hyperbolic", "misaligned_\udcffhyperbolic")
            .encode("utf-8", "surrogateescape"),
            "latin1.yaml": '%YAML:1.0\nmodel: "caf\xe9"\n'.encode("latin-1"),
            "alias.yaml": b"%YAML:1.0\n---\na: &x 1\nb: *x\n",
            "tags.yaml": b"%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: 3\n   cols: 3\n"
            b"   dt: u\n   data: [ 583, 0, 0, 0, 583, 0, 0, 0, 1 ]\n",
            "longline.json": ("[" + "1," * 200000 + "1]").encode(),
            "crlf.yaml": render(base_fields(self.cam), "yaml").replace("\n", "\r\n").encode(),
            "xmlent.xml": b'<?xml version="1.0"?>\n<!DOCTYPE a [<!ENTITY x "xxxxxxxxxx">]>\n'
            b"<opencv_storage><a>&x;&x;&x;</a></opencv_storage>\n",
            "longkey.yaml": b"%YAML:1.0\n---\n" + b"k" * 100000 + b": 1\n",
            "longstr.yaml": b'%YAML:1.0\n---\nmodel: "' + b"m" * 100000 + b'"\n',
            "longstr.xml": b'<?xml version="1.0"?>\n<opencv_storage><model>'
            + b"m" * 100000
            + b"</model></opencv_storage>\n",
            "longtag.xml": b'<?xml version="1.0"?>\n<opencv_storage><'
            + b"t" * 100000
            + b">1</"
            + b"t" * 100000
            + b"></opencv_storage>\n",
            "manykeys.yaml": b"%YAML:1.0\n---\n"
            + b"".join(b"k%d: %d\n" % (i, i) for i in range(60000)),
            "attrs.xml": b'<?xml version="1.0"?>\n<opencv_storage><K type_id="opencv-matrix" '
            + b" ".join(b'a%d="1"' % i for i in range(20000))
            + b"><rows>1</rows></K></opencv_storage>\n",
            "unclosed.xml": b'<?xml version="1.0"?>\n<opencv_storage><K type_id="opencv-matrix">'
            b"<rows>3</rows><cols>3<dt>d</dt><data>1 2 3",
            "badmat.yaml": b"%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: 3\n   cols: 3\n"
            b'   dt: "3d"\n   data: [ 1, 2, 3 ]\n',
            "rowsbig.yaml": b"%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: 2147483647\n"
            b"   cols: 2147483647\n   dt: d\n   data: [ 1, 2, 3 ]\n",
        }
        for name, data in files.items():
            with open(os.path.join(d, name), "wb") as f:
                f.write(data)
            cases.append((name, name.split(".")[0], {}))
        bad_name = os.path.join(os.fsencode(d), b"calib\xff\xfe.yaml")
        with open(bad_name, "wb") as f:
            f.write(render(base_fields(self.cam), "yaml").encode())
        cases.append((os.fsdecode(b"calib\xff\xfe.yaml"), "a non-UTF-8 name", {}))
        for name, desc, extra in cases:
            p = os.path.join(d, name)
            shown = p.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
            base = {"path": p, "shown": shown, **extra}
            if name.endswith((".yaml", ".yml", ".xml", ".json")):
                what = "calibration"
                self.run(
                    "special files",
                    f"load: {desc}",
                    {"kind": "load", "what": what, "desc": desc, **base},
                )
                self.run(
                    "special files",
                    f"read_intrinsics: {desc}",
                    {"kind": "load", "what": "intrinsics", "desc": desc, **base},
                )
                self.run(
                    "special files", f"omnicam info: {desc}", {"kind": "cli", "argv": ["info", p]}
                )
            if name.endswith(".json") or desc in ("a folder", "a FIFO", "a missing file"):
                self.run(
                    "special files",
                    f"read_far_lines: {desc}",
                    {"kind": "load", "what": "far_lines", "desc": desc, **base},
                )
        # the worker must survive a few dozen corrupt json files in one process
        for i in range(30):
            src = (
                files["model_ff.json"] if i % 2 else render(base_fields(self.cam), "json").encode()
            )
            data, desc = byte_mutant(self.rnd, src)
            p = os.path.join(d, f"heap{i}.json")
            with open(p, "wb") as f:
                f.write(data)
            self.run(
                "special files",
                f"corrupt json in one process #{i} ({desc})",
                {"kind": "load", "what": "calibration", "path": p},
            )

    def messages(self):
        """Issue 18 item 8: messages that name the thing (the file, the field, the line, what
        a file is) and what to do; each case names the words its message must hold."""
        import cv2
        import numpy as np

        d = os.path.dirname(self.path("item8", "x"))
        cam = self.cam
        cat = "messages (issue 18 item 8)"

        def opencv_json(name, rim_radius=30.0, K=None, confidence=0.5):
            p = os.path.join(d, name)
            fs = cv2.FileStorage(p, cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_JSON)
            fs.write("format_version", 1)
            fs.write("model", "misaligned_hyperbolic")
            fs.startWriteStruct("mirror", cv2.FILE_NODE_MAP)
            for k, v in (("a", cam.mirror.a), ("b", cam.mirror.b), ("rim_radius", rim_radius)):
                fs.write(k, v)
            fs.endWriteStruct()
            fs.write("K", cam.K if K is None else K)
            fs.write("rvec", cam.rvec.reshape(3, 1))
            fs.write("tvec", cam.tvec.reshape(3, 1))
            fs.startWriteStruct("verdict", cv2.FILE_NODE_MAP)
            fs.write("confidence", confidence)
            fs.endWriteStruct()
            fs.release()
            return p

        K_inf = cam.K.copy()
        K_inf[0, 2] = -np.inf
        good = render(base_fields(cam), "json")
        yaml = render(base_fields(cam), "yaml")
        files = [  # (path, description, extra spec)
            (
                opencv_json("nan_verdict.json", confidence=float("nan")),
                ".Nan in the verdict",
                {"must_load": True},
            ),
            (
                opencv_json("nan_mirror.json", rim_radius=float("nan")),
                ".Nan in mirror",
                {"refuse": True, "must_name": ["'mirror.rim_radius'", "finite"]},
            ),
            (
                opencv_json("inf_mirror.json", rim_radius=float("inf")),
                ".Inf in mirror",
                {"refuse": True, "must_name": ["'mirror.rim_radius'", "finite"]},
            ),
            (
                opencv_json("inf_K.json", K=K_inf),
                "-.Inf in K",
                {"refuse": True, "must_name": ["'K'", "finite"]},
            ),
        ]
        texts = {
            "bigint.json": (
                good.replace('"format_version": 1', '"format_version": ' + "7" * 5000),
                ["format_version", "line 2", "5000 digits"],
            ),
            "deepfield.json": (
                good.replace('"model"', '"deep": ' + "[" * 40 + "]" * 40 + ', "model"'),
                ["'deep'", "line 3", "nested too deeply"],
            ),
            "deepfield.yaml": (
                yaml.replace("rvec:", "deep: " + "[" * 40 + "]" * 40 + "\nrvec:"),
                ["'deep'", "nested too deeply"],
            ),
            "bigint.yaml": (
                yaml.replace("format_version: 1", "format_version: 4294967297"),
                ["'format_version'", "32 bits"],
            ),
            "syntax.json": (good.replace('"rows": 3,', '"rows": 3', 1), ["'K'", "line "]),
        }
        for name, (text, words) in texts.items():
            p = os.path.join(d, name)
            with open(p, "w") as f:
                f.write(text)
            files.append((p, name, {"refuse": True, "must_name": words}))
        data = good.encode()
        at = data.index(b"misaligned_hyperbolic") + 3
        p = os.path.join(d, "latin1.json")
        with open(p, "wb") as f:
            f.write(data[:at] + b"\xe9" + data[at:])
        line = data[:at].count(b"\n") + 1
        files.append(
            (p, "latin-1 in model", {"must_name": [f"line {line}", "'model'", f"byte {at}"]})
        )
        for path, desc, extra in files:
            self.run(
                cat,
                f"load {desc}",
                {"kind": "load", "what": "calibration", "path": path, "desc": desc, **extra},
            )
        for i, (label, _, _) in enumerate(API_CASES):
            if label.startswith("item8:"):
                self.run(cat, label, {"kind": "api", "index": i}, timeout=60)
        # images and videos: what the file is
        image = cv2.imread(self.image)
        ok, jpg = cv2.imencode(".jpg", image)
        jpg = jpg.tobytes()
        media = {
            "notes.txt": (b"calibration notes\nrig 3\n", ["notes.txt", "a text file"]),
            "notes.png": (b"calibration notes\n", ["notes.png", "a text file"]),
            "broken.mp4": (
                os.urandom(16),
                ["broken.mp4", "not a video OpenCV can open (16 bytes)"],
            ),
            "half.jpg": (jpg[: len(jpg) // 2], ["half.jpg", "truncated JPEG"]),
            "cut.jpg": (jpg[:-2], ["cut.jpg", "truncated JPEG"]),
        }
        out = self.path("item8out", "o.png")
        k = self.path("good", "k.yaml")
        for name, (content, words) in media.items():
            p = os.path.join(d, name)
            with open(p, "wb") as f:
                f.write(content)
            argv = ["unwarp", p, "-c", self.calib, "--panorama", "128x32", "-o", out, "--overwrite"]
            self.run(
                cat, f"unwarp {name}", {"kind": "cli", "argv": argv, "rc": (1,), "must_name": words}
            )
        strips = {"wide.png": (500, 4000), "tall.png": (4000, 500)}
        for name, shape in strips.items():
            p = os.path.join(d, name)
            cv2.imwrite(p, cv2.resize(image, shape[::-1]))
        for name, words in (
            ("half.jpg", ["half.jpg", "truncated JPEG"]),
            ("wide.png", ["wide.png", "4000x500 (8.0:1)"]),
            ("tall.png", ["tall.png", "500x4000 (8.0:1)"]),
        ):
            argv = [
                "calibrate",
                os.path.join(d, name),
                "--mirror",
                "23.4",
                "28.1",
                "30",
                "--intrinsics",
                k,
                "-o",
                self.path("item8out", "c.yaml"),
                "--overwrite",
                "--no-refine",
            ]
            self.run(
                cat,
                f"calibrate {name}",
                {"kind": "cli", "argv": argv, "rc": (1,), "must_name": words},
                timeout=180,
            )

    def api(self, limit=None):
        idx = list(range(len(API_CASES)))
        if limit is not None and limit < len(idx):
            idx = sorted(self.rnd.sample(idx, limit))
        for i in idx:
            self.run(
                "API arguments",
                f"api #{i} {API_CASES[i][0]}",
                {"kind": "api", "index": i},
                timeout=60,
            )

    def cli_args(self, n):
        rnd = self.rnd
        img, calib, k = self.image, self.calib, self.path("good", "k.yaml")
        out_png = self.path("cliout", "o.png")
        toks = [
            "nan",
            "inf",
            "-1",
            "0",
            "abc",
            "1e400",
            "",
            "1x1",
            "0x0",
            "99999x99999",
            "ab",
            "10x",
            "-5x3",
            "1e3",
            "32768x2",
            "\udcff",
            "--",
            "-",
            "3.5",
        ]
        templates = [
            ["unwarp", img, "-c", calib, "--panorama", "{t}", "-o", out_png, "--overwrite"],
            [
                "unwarp",
                img,
                "-c",
                calib,
                "--panorama",
                "128x32",
                "--elevation",
                "{t}",
                "{t}",
                "-o",
                out_png,
                "--overwrite",
            ],
            [
                "unwarp",
                img,
                "-c",
                calib,
                "--perspective",
                "64x48",
                "--fov",
                "{t}",
                "-o",
                out_png,
                "--overwrite",
            ],
            [
                "unwarp",
                img,
                "-c",
                calib,
                "--perspective",
                "64x48",
                "--fov",
                "60",
                "--yaw",
                "{t}",
                "--pitch",
                "{t}",
                "-o",
                out_png,
                "--overwrite",
            ],
            [
                "unwarp",
                img,
                "-c",
                calib,
                "--panorama",
                "128x32",
                "--depth",
                "{t}",
                "-o",
                out_png,
                "--overwrite",
            ],
            [
                "unwarp",
                img,
                "-c",
                calib,
                "--panorama",
                "128x32",
                "--projection",
                "{t}",
                "-o",
                out_png,
                "--overwrite",
            ],
            ["unwarp", "{t}", "-c", calib, "--panorama", "128x32", "-o", out_png, "--overwrite"],
            ["unwarp", img, "-c", "{t}", "--panorama", "128x32", "-o", out_png, "--overwrite"],
            ["unwarp", img, "-c", calib, "--panorama", "128x32", "-o", "{t}", "--overwrite"],
            [
                "unwarp",
                self.video,
                "-c",
                calib,
                "--panorama",
                "128x32",
                "-o",
                self.path("cliout", "o.avi"),
                "--overwrite",
                "--quiet",
                "--max-frames",
                "{t}",
            ],
            [
                "unwarp",
                self.video,
                "-c",
                calib,
                "--panorama",
                "128x32",
                "-o",
                self.path("cliout", "o.avi"),
                "--overwrite",
                "--quiet",
                "--fourcc",
                "{t}",
            ],
            [
                "calibrate",
                img,
                "--mirror",
                "{t}",
                "23",
                "30",
                "--intrinsics",
                k,
                "-o",
                self.path("cliout", "c.yaml"),
                "--overwrite",
            ],
            [
                "calibrate",
                img,
                "--mirror",
                "23.4",
                "28.1",
                "30",
                "--intrinsics",
                "{t}",
                "-o",
                self.path("cliout", "c.yaml"),
                "--overwrite",
            ],
            [
                "calibrate",
                img,
                "--mirror",
                "23.4",
                "28.1",
                "30",
                "--intrinsics",
                k,
                "--far-lines",
                "{t}",
                "-o",
                self.path("cliout", "c.yaml"),
                "--overwrite",
            ],
            ["calibrate", img, "--mirror", "23.4", "28.1", "30", "--intrinsics", k, "-o", "{t}"],
            [
                "unwarp",
                self.video,
                "-c",
                calib,
                "--panorama",
                "128x32",
                "-o",
                self.path("cliout", "o.mp4"),
                "--overwrite",
                "--quiet",
                "--fourcc",
                "{f}",
            ],
            ["info", "{t}"],
            ["{t}"],
            ["info"],
            ["calibrate"],
            ["unwarp"],
            [],
            ["unwarp", img, "-c", calib, "-o", out_png],
            [
                "unwarp",
                img,
                "-c",
                calib,
                "--panorama",
                "128x32",
                "--perspective",
                "64x48",
                "-o",
                out_png,
            ],
        ]
        for i in range(n):
            tpl = templates[i % len(templates)]
            fourccs = ["H264", "avc1", "XVID", "MJPG", "zzzz", "mp4v", "hev1", "\0\0\0\0"]
            argv = [
                rnd.choice(toks) if t == "{t}" else rnd.choice(fourccs) if t == "{f}" else t
                for t in tpl
            ]
            expensive = (
                bool(argv) and argv[0] == "calibrate" and all(t not in toks for t in argv[1:])
            )
            self.run(
                "CLI arguments",
                " ".join(map(repr, argv)),
                {"kind": "cli", "argv": argv},
                timeout=180 if expensive else None,
            )

    def media(self, n_images, n_videos):
        """Corrupt and truncated images and videos through `omnicam unwarp` / `calibrate`."""
        rnd = self.rnd
        srcs = {
            ext: open(self.path("good", f"mirror{ext}"), "rb").read()
            for ext in (".png", ".jpg", ".tif")
        }
        out_png = self.path("mediaout", "o.png")
        for i in range(n_images):
            ext = rnd.choice(list(srcs))
            data = srcs[ext]
            op = rnd.choice(["truncate", "flip", "empty", "garbage", "header", "zero_tail"])
            if op == "truncate":
                data = data[: rnd.randrange(1, len(data))]
            elif op == "flip":
                b = bytearray(data)
                for _ in range(rnd.randint(1, 20)):
                    j = rnd.randrange(len(b))
                    b[j] ^= 1 << rnd.randrange(8)
                data = bytes(b)
            elif op == "empty":
                data = b""
            elif op == "garbage":
                data = os.urandom(rnd.randint(1, 5000))
            elif op == "header":
                data = data[:16] + os.urandom(200)
            else:
                data = data[: len(data) // 2] + b"\0" * (len(data) // 2)
            p = self.path("media", f"img{i}{ext}")
            with open(p, "wb") as f:
                f.write(data)
            if i % 8 == 7:
                argv = [
                    "calibrate",
                    p,
                    "--mirror",
                    "23.4",
                    "28.1",
                    "30",
                    "--intrinsics",
                    self.path("good", "k.yaml"),
                    "-o",
                    self.path("mediaout", "c.yaml"),
                    "--overwrite",
                    "--no-refine",
                ]
            else:
                argv = [
                    "unwarp",
                    p,
                    "-c",
                    self.calib,
                    "--panorama",
                    "128x32",
                    "-o",
                    out_png,
                    "--overwrite",
                ]
            self.run(
                "corrupt images",
                f"{op} {ext} via {argv[0]}",
                {"kind": "cli", "argv": argv, "must_name": [os.path.basename(p)]},
                timeout=180,
            )
        for ext in (".png", ".avi"):
            src = self.image if ext == ".png" else self.video
            bad = os.path.join(os.fsencode(self.path("media", "x")[:-1]), b"in\xff" + ext.encode())
            shutil.copy(src, bad)
            out = self.path("mediaout", "o" + (".png" if ext == ".png" else ".avi"))
            self.run(
                "corrupt images" if ext == ".png" else "corrupt videos",
                f"a non-UTF-8 input name {ext}",
                {
                    "kind": "cli",
                    "argv": [
                        "unwarp",
                        os.fsdecode(bad),
                        "-c",
                        self.calib,
                        "--panorama",
                        "128x32",
                        "-o",
                        out,
                        "--overwrite",
                        "--quiet",
                    ],
                },
                timeout=120,
            )
        vsrc = open(self.video, "rb").read()
        for i in range(n_videos):
            op = rnd.choice(["truncate", "flip", "empty", "garbage", "zero_tail"])
            data = vsrc
            if op == "truncate":
                data = data[: rnd.randrange(1, len(data))]
            elif op == "flip":
                b = bytearray(data)
                for _ in range(rnd.randint(1, 40)):
                    j = rnd.randrange(len(b))
                    b[j] ^= 1 << rnd.randrange(8)
                data = bytes(b)
            elif op == "empty":
                data = b""
            elif op == "garbage":
                data = os.urandom(rnd.randint(1, 50000))
            else:
                data = data[: len(data) // 2] + b"\0" * (len(data) // 2)
            ext = rnd.choice([".avi", ".mp4"])
            p = self.path("media", f"vid{i}{ext}")
            with open(p, "wb") as f:
                f.write(data)
            self.run(
                "corrupt videos",
                f"{op} {ext}",
                {
                    "kind": "cli",
                    "argv": [
                        "unwarp",
                        p,
                        "-c",
                        self.calib,
                        "--panorama",
                        "128x32",
                        "-o",
                        self.path("mediaout", "o.avi"),
                        "--overwrite",
                        "--quiet",
                    ],
                },
                timeout=120,
            )

    def saves(self):
        """Saves onto existing files and into odd places (the old file must survive)."""
        d = os.path.dirname(self.path("saves", "x"))
        for writer, ext in (
            ("camera", ".yaml"),
            ("camera", ".xml"),
            ("camera", ".json"),
            ("camera", ".yml"),
            ("intrinsics", ".yaml"),
            ("far_lines", ".json"),
        ):
            p = os.path.join(d, f"old_{writer}{ext}")
            with open(p, "wb") as f:
                f.write(b"old content that must survive a failed save\n")
            self.run(
                "saves",
                f"{writer}{ext} over an old file",
                {"kind": "save", "writer": writer, "path": p, "must_succeed": True},
            )
            # a stale temporary of a killed writer is removed by the next save
            stale = os.path.join(d, f".old_{writer}{TEMP_MARK}999999-deadbeef{ext}")
            with open(stale, "wb") as f:
                f.write(b"half")
            self.run(
                "saves",
                f"{writer}{ext} with a stale temporary",
                {"kind": "save", "writer": writer, "path": p, "must_succeed": True},
            )
            os.makedirs(os.path.join(d, f"dir_{writer}{ext}"), exist_ok=True)
            self.run(
                "saves",
                f"{writer}{ext} onto a folder",
                {
                    "kind": "save",
                    "writer": writer,
                    "path": os.path.join(d, f"dir_{writer}{ext}"),
                    "must_fail": True,
                    "desc": "a folder",
                },
            )
            self.run(
                "saves",
                f"{writer}{ext} into a missing folder",
                {
                    "kind": "save",
                    "writer": writer,
                    "path": os.path.join(d, "missing", f"c{ext}"),
                    "must_fail": True,
                    "desc": "missing folder",
                },
            )
            self.run(
                "saves",
                f"{writer}{ext} with a non-UTF-8 name",
                {
                    "kind": "save",
                    "writer": writer,
                    "path": os.path.join(d, f"bad\udcff{ext}"),
                    "desc": "non-UTF-8",
                },
            )

    # -- full disk and read-only folder (root: a small tmpfs) -------------------------------
    def _mount(self, name, size="64k"):
        mnt = self.path("mnt", name, "x")
        mnt = os.path.dirname(mnt)
        try:
            r = subprocess.run(
                ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", mnt],
                capture_output=True,
                text=True,
            )
        except OSError:  # no mount command
            return None
        if r.returncode != 0:
            return None
        self.mounts.append(mnt)
        return mnt

    def _fill(self, mnt, leave):
        """Fill ``mnt`` leaving about ``leave`` bytes free."""
        filler = os.path.join(mnt, "filler")
        with open(filler, "wb") as f:
            with contextlib.suppress(OSError):
                while True:
                    st = os.statvfs(mnt)
                    free = st.f_bavail * st.f_frsize
                    if free <= leave:
                        break
                    f.write(b"\0" * min(4096, max(1, free - leave)))
                    f.flush()
                    os.fsync(f.fileno())

    def _old_files(self, mnt):
        import shutil as sh

        olds = {}
        for name, src in (
            ("c.yaml", self.good[("yaml", "")]),
            ("c.xml", self.good[("xml", "")]),
            ("c.json", self.good[("json", "")]),
            ("k.yaml", self.path("good", "k.yaml")),
            ("lines.json", self.path("good", "lines.json")),
        ):
            sh.copy(src, os.path.join(mnt, name))
            olds[name] = os.path.join(mnt, name)
        return olds

    def disks(self, levels=(0, 1024, 3000, 6000, 12000)):
        if os.geteuid() != 0:
            self.skipped.append("full disk and read-only folder: not root (need mount)")
            return
        for leave in levels:
            mnt = self._mount(f"full{leave}")
            if mnt is None:
                self.skipped.append("full disk: mount -t tmpfs failed")
                return
            olds = self._old_files(mnt)
            with open(os.path.join(mnt, "old.png"), "wb") as f:
                f.write(b"\x89PNG-old-output")
            self._fill(mnt, leave)
            cat = f"full disk ({leave} B free)"
            for name, writer in (
                ("c.yaml", "camera"),
                ("c.xml", "camera"),
                ("c.json", "camera"),
                ("k.yaml", "intrinsics"),
                ("lines.json", "far_lines"),
            ):
                self.run(
                    cat, f"save {name}", {"kind": "save", "writer": writer, "path": olds[name]}
                )
            self.run(
                cat,
                "omnicam calibrate -o on a full disk",
                {
                    "kind": "cli_write",
                    "keep": [olds["c.yaml"]],
                    "argv": [
                        "calibrate",
                        self.image,
                        "--mirror",
                        "23.4",
                        "28.1",
                        "30",
                        "--intrinsics",
                        self.path("good", "k.yaml"),
                        "-o",
                        olds["c.yaml"],
                        "--overlay",
                        self.path("cliout", "ov.png"),
                        "--overwrite",
                        "--no-refine",
                    ],
                },
                timeout=240,
            )
            self.run(
                cat,
                "omnicam unwarp image on a full disk",
                {
                    "kind": "cli_write",
                    "keep": [os.path.join(mnt, "old.png")],
                    "must_fail": True,
                    "argv": [
                        "unwarp",
                        self.image,
                        "-c",
                        self.calib,
                        "--panorama",
                        "512x128",
                        "-o",
                        os.path.join(mnt, "old.png"),
                        "--overwrite",
                    ],
                },
            )
            old_video = os.path.join(mnt, "old.avi")
            with contextlib.suppress(OSError):
                with open(old_video, "wb") as f:
                    f.write(b"RIFF-old-video")
            if os.path.exists(old_video):
                self.run(
                    cat,
                    "omnicam unwarp video on a full disk",
                    {
                        "kind": "cli_write",
                        "keep": [old_video],
                        "must_fail": True,
                        "argv": [
                            "unwarp",
                            self.video,
                            "-c",
                            self.calib,
                            "--panorama",
                            "256x64",
                            "-o",
                            old_video,
                            "--overwrite",
                            "--quiet",
                        ],
                    },
                    timeout=120,
                )
        # read-only: a tmpfs remounted read-only
        mnt = self._mount("ro", "1m")
        if mnt is None:
            return
        olds = self._old_files(mnt)
        with open(os.path.join(mnt, "old.png"), "wb") as f:
            f.write(b"\x89PNG-old-output")
        r = subprocess.run(["mount", "-o", "remount,ro", mnt], capture_output=True)
        if r.returncode != 0:  # (mount exists: the tmpfs above was mounted with it)
            self.skipped.append("read-only folder: remount,ro failed")
            return
        cat = "read-only folder"
        for name, writer in (
            ("c.yaml", "camera"),
            ("c.xml", "camera"),
            ("c.json", "camera"),
            ("k.yaml", "intrinsics"),
            ("lines.json", "far_lines"),
        ):
            self.run(
                cat,
                f"save {name}",
                {
                    "kind": "save",
                    "writer": writer,
                    "path": olds[name],
                    "must_fail": True,
                    "desc": "read-only",
                },
            )
            self.run(
                cat,
                f"load {name}",
                {
                    "kind": "load",
                    "what": {
                        "camera": "calibration",
                        "intrinsics": "intrinsics",
                        "far_lines": "far_lines",
                    }[writer],
                    "path": olds[name],
                },
            )
        self.run(
            cat,
            "omnicam calibrate -o into a read-only folder",
            {
                "kind": "cli_write",
                "keep": [olds["c.yaml"]],
                "must_fail": True,
                "argv": [
                    "calibrate",
                    self.image,
                    "--mirror",
                    "23.4",
                    "28.1",
                    "30",
                    "--intrinsics",
                    self.path("good", "k.yaml"),
                    "-o",
                    olds["c.yaml"],
                    "--overlay",
                    self.path("cliout", "ov2.png"),
                    "--overwrite",
                    "--no-refine",
                ],
            },
            timeout=240,
        )
        self.run(
            cat,
            "omnicam unwarp image into a read-only folder",
            {
                "kind": "cli_write",
                "keep": [os.path.join(mnt, "old.png")],
                "must_fail": True,
                "argv": [
                    "unwarp",
                    self.image,
                    "-c",
                    self.calib,
                    "--panorama",
                    "128x32",
                    "-o",
                    os.path.join(mnt, "old.png"),
                    "--overwrite",
                ],
            },
        )
        self.run(
            cat,
            "omnicam info from a read-only folder",
            {"kind": "cli", "argv": ["info", olds["c.yaml"]], "rc": (0,)},
        )

    def permissions(self):
        if os.geteuid() != 0:
            self.skipped.append("permission cases: not root (cannot switch to user nobody)")
            return
        import pwd

        try:
            uid = pwd.getpwnam("nobody").pw_uid
        except KeyError:
            self.skipped.append("permission cases: no user nobody")
            return
        d = os.path.dirname(self.path("perm", "x"))
        os.chmod(self.workdir, 0o755)
        os.chmod(os.path.dirname(d), 0o755)
        os.chmod(d, 0o755)
        worker = Worker(self.workdir, user=uid)
        try:
            for ext in (".yaml", ".xml", ".json"):
                p = os.path.join(d, f"secret{ext}")
                shutil.copy(self.good[(ext[1:], "")], p)
                os.chmod(p, 0o000)
                self.run(
                    "permissions (user nobody)",
                    f"load unreadable {ext}",
                    {"kind": "load", "what": "calibration", "path": p},
                    worker=worker,
                )
                self.run(
                    "permissions (user nobody)",
                    f"read_intrinsics unreadable {ext}",
                    {"kind": "load", "what": "intrinsics", "path": p},
                    worker=worker,
                )
                p2 = os.path.join(d, f"old{ext}")
                shutil.copy(self.good[(ext[1:], "")], p2)
                os.chmod(p2, 0o644)
                self.run(
                    "permissions (user nobody)",
                    f"save into a folder not writable {ext}",
                    {
                        "kind": "save",
                        "writer": "camera",
                        "path": p2,
                        "must_fail": True,
                        "desc": "no write permission",
                    },
                    worker=worker,
                )
            self.run(
                "permissions (user nobody)",
                "omnicam info unreadable",
                {"kind": "cli", "argv": ["info", os.path.join(d, "secret.yaml")]},
                worker=worker,
            )
            outdir = os.path.join(d, "out")  # writable, so that only the input is refused
            os.makedirs(outdir, exist_ok=True)
            os.chmod(outdir, 0o777)
            for name, src in (("secret.png", self.image), ("secret.avi", self.video)):
                p = os.path.join(d, name)
                shutil.copy(src, p)
                os.chmod(p, 0o000)
                argv = [
                    "unwarp",
                    p,
                    "-c",
                    self.calib,
                    "--panorama",
                    "64x16",
                    "-o",
                    os.path.join(outdir, "o" + os.path.splitext(name)[1]),
                    "--overwrite",
                ]
                self.run(
                    "permissions (user nobody)",
                    f"omnicam unwarp unreadable {name}",
                    {
                        "kind": "cli",
                        "argv": argv,
                        "rc": (1,),
                        "must_name": [name, "permission denied"],
                    },
                    worker=worker,
                )
        finally:
            worker.close()

    # -- SIGINT at random moments (subprocesses of the CLI and of a saving loop) --------------
    def sigint(self, n_video, n_save, n_calib):
        rnd = self.rnd
        env = dict(os.environ, PYTHONPATH=REPO)
        env.pop("OMNICAM_DEBUG", None)
        # what a user runs: the console script (its SIGINT handling starts at import)
        script_path = os.path.join(os.path.dirname(sys.executable), "omnicam")
        if os.path.exists(script_path):
            command = [script_path]
        else:
            entry = "import sys; from omnicam.cli import main; sys.exit(main(sys.argv[1:]))"
            command = [sys.executable, "-c", entry]
        d = os.path.dirname(self.path("sigint", "x"))
        for i in range(n_video):
            out = os.path.join(d, f"v{i}.avi")
            shutil.copy(self.video, out)  # an earlier complete output
            before = _snapshot(out)
            delay = rnd.uniform(0.0, 6.0)
            argv = [
                "unwarp",
                self.long_video,
                "-c",
                self.calib,
                "--panorama",
                "512x128",
                "-o",
                out,
                "--overwrite",
                "--quiet",
            ]
            self._interrupt(
                f"SIGINT during unwarp (video, --overwrite) at {delay:.2f} s",
                [*command, *argv],
                env,
                delay,
                d,
                keep={out: before},
            )
        for i in range(n_calib):
            out = os.path.join(d, f"c{i}.yaml")
            shutil.copy(self.calib, out)
            before = _snapshot(out)
            delay = rnd.uniform(0.0, 8.0)
            argv = [
                "calibrate",
                self.image,
                "--mirror",
                "23.4",
                "28.1",
                "30",
                "--intrinsics",
                self.path("good", "k.yaml"),
                "-o",
                out,
                "--overlay",
                os.path.join(d, f"ov{i}.png"),
                "--overwrite",
            ]
            self._interrupt(
                f"SIGINT during calibrate at {delay:.2f} s",
                [*command, *argv],
                env,
                delay,
                d,
                keep={out: before},
                new_ok=True,
                loads=out,
            )
        script = (
            "import sys, numpy as np\nfrom omnicam import synthetic\n"
            "cam = synthetic.misaligned_rig()\nother = cam.replace(D=[0.1, 0, 0, 0, 0])\n"
            "cam.save(sys.argv[1])\nprint('ready', flush=True)\n"
            "i = 0\ntry:\n    while True:\n"
            "        (cam if i % 2 else other).save(sys.argv[1])\n"
            "        i += 1\nexcept KeyboardInterrupt:\n    print('interrupted', i)\n"
        )
        for i in range(n_save):
            ext = rnd.choice([".yaml", ".xml", ".json"])
            out = os.path.join(d, f"s{i}{ext}")
            shutil.copy(self.good[(ext[1:], "")], out)
            delay = rnd.uniform(0.5, 4.0)
            self._interrupt(
                f"SIGINT during a loop of saves ({ext}) at {delay:.2f} s",
                [sys.executable, "-c", script, out],
                env,
                delay,
                d,
                keep={out: None},
                rc=(0,),
                loads=out,
                wait_ready=True,
            )

    def sigkill_saves(self, n):
        """SIGKILL mid-save: the file stays loadable; the next save removes the temporary."""
        rnd = self.rnd
        env = dict(os.environ, PYTHONPATH=REPO)
        script = (
            "import sys\nfrom omnicam import synthetic\n"
            "cam = synthetic.misaligned_rig()\nother = cam.replace(D=[0.1, 0, 0, 0, 0])\n"
            "cam.save(sys.argv[1])\nprint('ready', flush=True)\ni = 0\nwhile True:\n"
            "    (cam if i % 2 else other).save(sys.argv[1])\n    i += 1\n"
        )
        for i in range(n):
            ext = rnd.choice([".yaml", ".xml", ".json"])
            d = os.path.dirname(self.path("sigkill", f"k{i}", "x"))
            out = os.path.join(d, f"c{ext}")
            p = subprocess.Popen(
                [sys.executable, "-c", script, out],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                env=env,
            )
            p.stdout.readline()
            time.sleep(rnd.uniform(0.0, 1.0))
            p.kill()
            p.communicate()
            result = self.worker.run(
                {
                    "kind": "save",
                    "writer": "camera",
                    "path": out,
                    "must_succeed": True,
                    "loads_first": True,
                },
                self.args.timeout,
            )
            self.record("SIGKILL during save", f"{ext} #{i}", result)

    def _interrupt(
        self,
        label,
        cmd,
        env,
        delay,
        folder,
        keep,
        new_ok=False,
        rc=(0, 130),
        loads=None,
        wait_ready=False,
    ):
        t0 = time.perf_counter()
        p = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, cwd=folder
        )
        if wait_ready:
            p.stdout.readline()
        time.sleep(delay)
        p.send_signal(signal.SIGINT)
        try:
            out, err = p.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            p.kill()
            p.communicate()
            self.record("SIGINT", label, {"status": "bad", "detail": "hang after SIGINT"})
            return
        err = err.decode("utf-8", "replace")
        status, detail = "ok", f"rc {p.returncode} after {time.perf_counter() - t0:.1f} s"
        lines = [ln for ln in err.splitlines() if ln.strip()]
        # a SIGINT after the work is done (the outputs written and announced) arrives during
        # the interpreter's shutdown, where Python dies by the signal itself: not a fault
        done_then_killed = (
            p.returncode == -signal.SIGINT and not lines and b"wrote " in out and new_ok
        )
        if done_then_killed:
            detail = "interrupted after it wrote its outputs (during interpreter shutdown)"
        elif p.returncode not in rc:
            status, detail = "bad", f"exit status {p.returncode}; stderr {lines[-2:]}"
        elif p.returncode != 0 and (len(lines) != 1 or not lines[0].startswith("omnicam: ")):
            status, detail = "bad", f"exit {p.returncode} with stderr {lines[:3]}"
        elif p.returncode == 0 and lines and rc != (0,):
            if any(not ln.startswith("omnicam: ") for ln in lines):
                status, detail = "bad", f"stray stderr {lines[:3]}"
        for path, before in keep.items():
            now = _snapshot(path)
            if before is not None and now != before and not (p.returncode == 0 or new_ok):
                status, detail = (
                    "bad",
                    f"rc {p.returncode}: the earlier output "
                    f"{os.path.basename(path)} was replaced ({len(before)} -> "
                    f"{len(now or b'')} bytes)",
                )
        if loads:
            import omnicam

            try:
                omnicam.MisalignedHyperbolicCamera.load(loads)
            except Exception as e:
                status, detail = "bad", f"after SIGINT the file does not load: {e}"
        left = _temps(folder)
        if left:
            status, detail = "bad", f"temporary files left after SIGINT: {left}"
            for n in left:
                with contextlib.suppress(OSError):
                    os.remove(os.path.join(folder, n))
        self.record("SIGINT", label, {"status": status, "detail": detail})

    # -- everything -------------------------------------------------------------------------
    def main(self):
        q = self.args.quick
        t0 = time.perf_counter()
        try:
            self.setup()
            self.worker.start()
            steps = [
                (
                    "file mutants",
                    lambda: self.file_mutants(60 if q else 400, 40 if q else 600, 10 if q else 5),
                ),
                ("intrinsics", lambda: self.intrinsics_mutants(20 if q else 120)),
                ("far lines", lambda: self.far_line_mutants(20 if q else 80)),
                ("special files", self.special_files),
                ("messages", self.messages),
                ("api", lambda: self.api(80 if q else None)),
                ("cli", lambda: self.cli_args(25 if q else 150)),
                ("media", lambda: self.media(6 if q else 60, 2 if q else 20)),
                ("saves", self.saves),
                ("disks", lambda: self.disks((0,) if q else (0, 1024, 3000, 6000, 12000))),
                ("permissions", lambda: None if q else self.permissions()),
                # Ctrl-C at random moments only in the full run: its outcome depends on timing,
                # and CI must not pass or fail by chance (the full run's count is the figure)
                ("sigint", lambda: None if q else self.sigint(8, 8, 4)),
                ("sigkill", lambda: self.sigkill_saves(2 if q else 20)),
            ]
            for name, step in steps:
                if self.args.only and name not in self.args.only:
                    continue
                n0, s0 = self.n, time.perf_counter()
                try:
                    step()
                except Exception:
                    self.record(
                        "harness", name, {"status": "bad", "detail": traceback.format_exc()[-600:]}
                    )
                print(
                    f"[{name}: {self.n - n0} cases in {time.perf_counter() - s0:.0f} s]", flush=True
                )
        finally:
            self.worker.close()
            for mnt in reversed(self.mounts):
                with contextlib.suppress(OSError):
                    subprocess.run(["umount", "-l", mnt], capture_output=True)
            if not self.args.keep:
                shutil.rmtree(self.workdir, ignore_errors=True)
        return self.report(time.perf_counter() - t0)

    def report(self, seconds):
        print(f"\nomnicam fuzz: seed {self.args.seed}, {self.n} cases in {seconds:.0f} s")
        width = max((len(c) for c in self.counts), default=10)
        for cat in self.counts:
            c = self.counts[cat]
            print(f"  {cat:<{width}}  ok {c['ok']:5d}  bad {c['bad']:4d}")
        total = collections.Counter()
        for c in self.counts.values():
            total.update(c)
        print(f"  {'total':<{width}}  ok {total['ok']:5d}  bad {total['bad']:4d}")
        for s in self.skipped:
            print(f"  skipped: {s}")
        if self.bad:
            print("\nbad outcomes:")
            for cat, label, detail in self.bad[: None if self.args.verbose else 60]:
                print(f"  [{cat}] {label}: {detail}")
            if len(self.bad) > 60 and not self.args.verbose:
                print(f"  ... and {len(self.bad) - 60} more (-v shows all)")
        return 1 if self.bad else 0


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a few hundred cases (CI)")
    p.add_argument("--seed", type=int, default=20261201)
    p.add_argument("--timeout", type=float, default=60.0, help="seconds per case")
    p.add_argument("--only", nargs="*", help="run only these steps")
    p.add_argument("--keep", action="store_true", help="keep the work folder")
    p.add_argument("-v", "--verbose", action="store_true")
    p.add_argument("--worker", metavar="WORKDIR", help=argparse.SUPPRESS)
    p.add_argument("--as-user", type=int, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        worker_main(args.worker, args.as_user)
        return 0
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        # started in the background by a non-interactive shell (`cmd &`), SIGINT is ignored,
        # and an ignored signal stays ignored across exec: every child would then ignore the
        # Ctrl-C cases (a Python loop of saves ran on, "hang after SIGINT"). A user's terminal
        # delivers it; a handled signal is reset to the default on exec, as there
        signal.signal(signal.SIGINT, signal.default_int_handler)
    return Runner(args).main()


if __name__ == "__main__":
    sys.exit(main())
