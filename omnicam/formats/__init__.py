"""Files, one format concern a module: what omnicam reads and writes besides images and videos.

- :mod:`.filestorage`: the pre-scan and reader under omnicam's own files (``cv2.FileStorage``
  never crashes on them) and their verified atomic writer;
- :mod:`.calibration_file`: calibrations, with the :class:`~.verdict.Verdict` of
  :mod:`.verdict` (how far to trust them; each report builds its own);
- :mod:`.intrinsics`: a pinhole's ``K``, ``D`` and image size; the central models of
  ``cv2.omnidir`` and Kalibr read back;
- :mod:`.point_files`: pixels a user gives in files (far lines, rim boundary points,
  chessboard corners);
- :mod:`.other_tools`: other tools' files (ROS and Kalibr intrinsics read; cv2.omnidir,
  Kalibr-omni and OCamCalib calibrations recognised);
- :mod:`.central_fit`: the central models closest to the exact rig (the unified model of
  cv2.omnidir, Kalibr and camodocal; OCamCalib's polynomial);
- :mod:`.central_export`: those approximations in the tools' own files;
- :mod:`.maps`: remap tables as ffmpeg's ``remap`` maps and ``.npy``;
- :mod:`.spherical_metadata`: 360 metadata (Photo Sphere XMP in JPEG, spherical video boxes).

Every writer goes through :mod:`omnicam._atomic` (temporary file, fsync, read back, rename).
"""
