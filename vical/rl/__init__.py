"""vical.rl"""
