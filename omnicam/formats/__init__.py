"""Files, one format concern a module: what omnicam reads and writes besides images and videos.

- :mod:`.omnicam_files`: omnicam's own files (calibrations with their verdict, intrinsics, far
  lines), read defensively through ``cv2.FileStorage`` and written atomically;
- :mod:`.other_tools`: other tools' files (ROS and Kalibr intrinsics read; cv2.omnidir,
  Kalibr-omni and OCamCalib calibrations recognised);
- :mod:`.central_export`: central approximations of a calibration in other tools' formats
  (cv2.omnidir, Kalibr, camodocal, OCamCalib);
- :mod:`.maps`: remap tables as ffmpeg's ``remap`` maps and ``.npy``;
- :mod:`.spherical_metadata`: 360 metadata (Photo Sphere XMP in JPEG, spherical video boxes).

Every writer goes through :mod:`omnicam._atomic` (temporary file, fsync, read back, rename).
"""
