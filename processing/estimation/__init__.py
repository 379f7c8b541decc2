"""Estimation tools shared by every filter: consistency measures (NIS, NEES, innovation whiteness) in
``consistency``.
"""
