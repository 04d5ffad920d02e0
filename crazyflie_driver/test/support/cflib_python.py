"""Where Bitcraze's cflib lives for the peer tests: its own interpreter (cflib needs Python >= 3.10)."""
from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]


def cflib_python() -> str:
    """cflib's interpreter ($CFLIB_PYTHON, else the bootstrap's venv); skips with the reason."""
    explicit = os.environ.get("CFLIB_PYTHON")
    python = pathlib.Path(explicit) if explicit else REPO / ".ws" / "cflib-venv" / "bin" / "python3"
    if not python.exists():
        if sys.version_info < (3, 10):
            pytest.skip("cflib needs Python >= 3.10 (this is %d.%d)" % sys.version_info[:2])
        pytest.skip("cflib is not installed: run tools/bootstrap.sh --with-cflib")
    probe = subprocess.run([str(python), "-c", "import sys, cflib; print('%d.%d' % sys.version_info[:2])"],
                           capture_output=True, text=True, timeout=30)
    if probe.returncode != 0:
        version = subprocess.run([str(python), "-c", "import sys; print(sys.version_info >= (3, 10))"],
                                 stdout=subprocess.PIPE, text=True, timeout=30).stdout.strip()
        if version == "False":
            pytest.skip("cflib needs Python >= 3.10 (%s is older)" % python)
        pytest.skip("cflib is not importable by %s: run tools/bootstrap.sh --with-cflib" % python)
    return str(python)
