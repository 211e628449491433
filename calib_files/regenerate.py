"""Regenerate the sample calibration files from the canonical synthetic rigs.

    python calib_files/regenerate.py

Writes `calib_files/*.yaml` (the source) and the copies shipped inside the package
(`omnicam/data/`), which `omnicam.samples` reads; a test checks the two stay identical.
"""

import pathlib
import shutil

from omnicam import synthetic

HERE = pathlib.Path(__file__).resolve().parent
PACKAGE_DATA = HERE.parent / "omnicam" / "data"

RIGS = {
    "hyperomni_aligned.yaml": synthetic.aligned_rig(),
    "hyperomni_misaligned.yaml": synthetic.misaligned_rig(),
}

if __name__ == "__main__":
    for name, cam in RIGS.items():
        cam.save(HERE / name)
        shutil.copyfile(HERE / name, PACKAGE_DATA / name)
        print("wrote", HERE / name, "and", PACKAGE_DATA / name)
