"""charctl.nn"""
