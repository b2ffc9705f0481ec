"""vical.calib"""
