"""The console needs its optional extra (``pip install -e '.[console]'``; .ci/run has it)."""

import pytest

pytest.importorskip("starlette", reason="the console extra is not installed (.[console])")
pytest.importorskip("uvicorn", reason="the console extra is not installed (.[console])")
