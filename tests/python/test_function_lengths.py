"""No function over 100 lines in sim/, fit/ and python/ (issue 34), declarative tables excepted
(scripts/function_lengths.py, ALLOWED): a function longer than that is no longer read at once."""
import os
import shutil
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.mark.skipif(shutil.which("ctags") is None, reason="Universal Ctags (Debian: universal-ctags) not installed")
def test_no_function_is_over_100_lines():
    p = subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "function_lengths.py"), "--over", "100",
                        "--top", "5"], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 0, p.stdout + p.stderr
    longest = int(p.stdout.split()[0])
    assert 30 < longest <= 100   # the table is read (a broken ctags run would list nothing)
