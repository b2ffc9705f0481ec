"""vical.sim"""
