"""The mirror on ``omnicam calibrate``'s command line: any mirror of revolution from its data.

``--mirror A B RIM`` (the hyperboloid, in :mod:`.calibrate`) or one of: ``--sphere RADIUS
RIM``, ``--paraboloid R RIM``, ``--asphere R K RIM [--alpha A4 A6 ...]`` (each with
``--vertex-z Z``: the vertex's height above the camera's centre), ``--equiangular GAIN R0
RIM`` (Chahl & Srinivasan's mirror, ``R0`` the vertex's distance from the camera) or
``--mirror-file MIRROR.yaml`` (the ``mirror`` map of a calibration file, or of a file holding
only it: :func:`omnicam.formats.calibration_file.read_mirror`). Every mirror but the
hyperboloid is an :class:`omnicam.AsphericMirror`, its calibration a file of format 2.

The mirror frame is placed with the camera's nominal centre at its origin when ``--vertex-z``
is given (:func:`omnicam.mirror.nominal_camera_z`), which the plausibility checks and
``--guess-k`` need; without it they are left out, and the report says so.
"""

from __future__ import annotations

from ..asphere import AsphericMirror
from ..formats.calibration_file import read_mirror
from ._common import CliError, finite_arg, one_line, positive_arg

__all__ = ["MIRROR_FLAGS", "add_mirror_options", "mirror_of_args"]

#: (argparse dest, flag) of every option here that gives the mirror
MIRROR_FLAGS = (
    ("sphere", "--sphere"),
    ("paraboloid", "--paraboloid"),
    ("asphere", "--asphere"),
    ("equiangular", "--equiangular"),
    ("mirror_file", "--mirror-file"),
)
#: the options that only qualify one of them
_QUALIFIERS = (("alpha", "--alpha"), ("vertex_z", "--vertex-z"))


def add_mirror_options(group):
    """Add the options of any mirror of revolution to the argparse ``group``."""
    group.add_argument(
        "--sphere",
        nargs=2,
        type=positive_arg,
        metavar=("RADIUS", "RIM"),
        help="a spherical mirror (mm): its RADIUS of curvature and the rim's radius RIM "
        "(with --vertex-z)",
    )
    group.add_argument(
        "--paraboloid",
        nargs=2,
        type=positive_arg,
        metavar=("R", "RIM"),
        help="a parabolic mirror Z = rho^2 / (2 R) (mm): its vertex radius R (twice the focal "
        "length) and RIM (with --vertex-z)",
    )
    group.add_argument(
        "--asphere",
        nargs=3,
        type=finite_arg,
        metavar=("R", "K", "RIM"),
        help="an even asphere as optical data sheets give it (mm): vertex radius R, conic "
        "constant K (0 sphere, -1 paraboloid, < -1 hyperboloid, else an ellipsoid) and RIM, "
        "with --alpha for its polynomial terms and --vertex-z",
    )
    group.add_argument(
        "--alpha",
        nargs="+",
        type=finite_arg,
        metavar="A",
        help="with --asphere: the coefficients (mm) of (rho / RIM)^4, ^6, ... (a data sheet's "
        "A4, A6, ... of rho^4, rho^6, ... are A4 RIM^4, A6 RIM^6, ...)",
    )
    group.add_argument(
        "--vertex-z",
        type=finite_arg,
        metavar="Z",
        help="with --sphere, --paraboloid or --asphere: the height of the mirror's vertex "
        "above the camera's centre along the mirror axis, as the rig was built (mm). It "
        "places the camera's nominal centre at the mirror frame's origin, for the "
        "plausibility checks and --guess-k; without it those are left out",
    )
    group.add_argument(
        "--equiangular",
        nargs=3,
        type=positive_arg,
        metavar=("GAIN", "R0", "RIM"),
        help="Chahl & Srinivasan's equiangular mirror (mm): its GAIN (alpha > 1), R0 the "
        "vertex's distance from the camera's centre, and RIM (fitted by an even asphere to "
        "1e-6 of the aperture)",
    )
    group.add_argument(
        "--mirror-file",
        metavar="MIRROR.yaml",
        help="the mirror from a file: its 'mirror' map, {kind: even_asphere, R, k, alpha, "
        "rho_n, vertex_z, rim_radius} or {kind: hyperboloid, a, b, rim_radius}, alone or in "
        "an omnicam calibration file (yaml, yml, xml or json)",
    )


def given_flags(args):
    """The flags of this module's mirror options on the command line."""
    return [flag for dest, flag in MIRROR_FLAGS if getattr(args, dest, None) is not None]


def _qualifiers(args):
    return [flag for dest, flag in _QUALIFIERS if getattr(args, dest, None) is not None]


def mirror_of_args(args):
    """The mirror of this module's options, None when none is given, or a ``CliError``: more
    than one mirror, a qualifier of another (``--alpha`` without ``--asphere``), or a mirror
    the model refuses (naming the option)."""
    flags = given_flags(args) + (["--mirror"] if getattr(args, "mirror", None) else [])
    if len(flags) > 1:
        raise CliError(f"calibrate: give one mirror, not {' and '.join(flags)}", 2)
    qualifiers = _qualifiers(args)
    if not flags or flags[0] in ("--mirror", "--mirror-file", "--equiangular"):
        if qualifiers:
            raise CliError(
                f"calibrate: {qualifiers[0]} goes with --sphere, --paraboloid or --asphere"
                + (" (--alpha: --asphere)" if "--alpha" in qualifiers else ""),
                2,
            )
        if not flags or flags[0] == "--mirror":
            return None
    flag = flags[0]
    if args.alpha is not None and flag != "--asphere":
        raise CliError("calibrate: --alpha goes with --asphere", 2)
    vz = 0.0 if args.vertex_z is None else args.vertex_z
    try:
        if flag == "--mirror-file":
            return read_mirror(args.mirror_file)
        if flag == "--sphere":
            return AsphericMirror.sphere(args.sphere[0], args.sphere[1], vertex_z=vz)
        if flag == "--paraboloid":
            return AsphericMirror.paraboloid(args.paraboloid[0], args.paraboloid[1], vertex_z=vz)
        if flag == "--asphere":
            R, k, rim = args.asphere
            return AsphericMirror(R, k, rim, tuple(args.alpha or ()), vertex_z=vz)
        return AsphericMirror.equiangular(*args.equiangular)
    except (FileNotFoundError, ValueError) as e:
        # the mirror's rim_radius is its RIM argument here, not the chessboards' --rim-radius
        raise CliError(f"{flag}: {one_line(e).replace('rim_radius', 'RIM')}") from None
