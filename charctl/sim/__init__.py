"""charctl.sim"""
