"""charctl.rl"""
