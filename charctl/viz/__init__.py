"""charctl.viz"""
