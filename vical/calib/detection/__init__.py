"""Finding the target in images: checkerboard (``checkerboard``, its names importable from here) and aprilgrid
corners with Kalibr's point ids, and the hint when the images show a checkerboard of another size than the one
given (``board_size``)."""

from vical.calib.detection.checkerboard import FIND_FLAGS, SMALL_SQUARE_FLAGS, detect_checkerboard

__all__ = ["FIND_FLAGS", "SMALL_SQUARE_FLAGS", "detect_checkerboard"]  # importable from here, as before the split
