"""vical.env"""
