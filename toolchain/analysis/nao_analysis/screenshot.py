"""Open report.html in headless Chromium: fail on any console message, save the first screen.

The report has no script, so any console line (an exception, a failed load, a log call) is a
problem. Manual check only (needs Debian's chromium; `toolchain/nao analyze --screenshot`
installs it); CI does not run it.
"""

import os
import re
import shutil
import subprocess
import tempfile

from . import AnalysisError

WINDOW = (1280, 900)
TIMEOUT_S = 120
_CONSOLE = re.compile(r":CONSOLE[:(]")


def _chromium():
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    raise AnalysisError("chromium not found: install Debian's package chromium "
                        "(toolchain/nao analyze --screenshot does it when run as root)")


def _run(args, profile):
    cmd = [_chromium(), "--headless", "--disable-gpu", "--no-sandbox", "--hide-scrollbars",
           "--user-data-dir=%s" % profile, "--enable-logging=stderr", "--v=0"] + args
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise AnalysisError("chromium did not finish within %d s" % TIMEOUT_S) from None
    if p.returncode != 0:
        raise AnalysisError("chromium exited with status %d: %s" % (p.returncode, p.stderr.strip()[-300:]))
    return p.stdout, p.stderr


def screenshot_report(html_path, png_path):
    """Loads html_path twice (DOM dump, then screenshot of WINDOW); raises AnalysisError on a
    console message, a missing heading or no screenshot. Returns the console-free DOM size."""
    url = "file://" + os.path.abspath(html_path)
    png_path = os.path.abspath(png_path)
    os.makedirs(os.path.dirname(png_path), exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="nao-chromium-") as profile:
        dom, log1 = _run(["--dump-dom", url], profile)
        if os.path.exists(png_path):
            os.remove(png_path)
        _, log2 = _run(["--screenshot=%s" % png_path, "--window-size=%d,%d" % WINDOW, url], profile)
    console = [line for line in (log1 + log2).splitlines() if _CONSOLE.search(line)]
    if console:
        raise AnalysisError("report.html logged %d console message(s) in Chromium, first: %s"
                            % (len(console), console[0].split("]", 1)[-1].strip()))
    if "Table 2" not in dom or "<img" not in dom:
        raise AnalysisError("report.html did not render its table and figures in Chromium (DOM dump)")
    if not os.path.isfile(png_path) or os.path.getsize(png_path) == 0:
        raise AnalysisError("chromium wrote no screenshot to %s" % png_path)
    return len(dom)
