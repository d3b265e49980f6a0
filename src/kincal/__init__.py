"""kincal: kinematic calibration of serial robots from URDF."""
