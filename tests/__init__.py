"""Makes ``tests`` a package so pytest puts the repo root (not tests/) on sys.path.

Without it, tests/conftest.py would put tests/ first on sys.path, and the mirrored
tests/aeroweaver_edge/ directory would shadow the real package as a namespace package
(the editable install's finder runs after the path finder).
"""
