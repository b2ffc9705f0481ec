"""vical.io"""
