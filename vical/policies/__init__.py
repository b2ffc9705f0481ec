"""vical.policies"""
