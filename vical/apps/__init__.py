"""vical.apps"""
