"""chaincomp status: an empty LCM URL is refused."""

import os
import subprocess
import sys

from helpers import ROOT, one_error_line


def test_status_empty_url_is_refused():
    # an empty --url used to open liblcm's default (LCM_DEFAULT_URL, else UDP multicast) without
    # a word; the environment here keeps even that in-process
    env = dict(os.environ, LCM_DEFAULT_URL="memq://")
    res = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "status", "--once", "--timeout", "0.1",
                          "--url", " "], capture_output=True, text=True, cwd=ROOT, timeout=60, env=env)
    one_error_line(res, "status", "--url", "empty")
