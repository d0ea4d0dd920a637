"""Collections: many galleries in one service, each with its own meshes, index,
calibration, preset and units."""
