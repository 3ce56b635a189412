"""Stand-in for the pytest-rerunfailures plugin that Taichi's tests/python/conftest.py imports: it only
sets `works_with_current_xdist`; no test is rerun."""

works_with_current_xdist = None
