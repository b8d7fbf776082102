"""charctl.eval"""
