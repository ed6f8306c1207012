"""Open a report page in headless Chromium (Debian's chromium-headless-shell, installed by
``scripts/setup.sh --tests``): a screenshot, and which of the page's images did not load."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

BROWSERS = ("chromium-headless-shell", "chromium", "chromium-browser")

# run in a copy of the page, beside it (so relative paths resolve the same way): after the load
# event, every <img> must be complete with a natural width (the browser decoded the file)
_PROBE = ('<script>window.addEventListener("load",()=>{const im=[...document.images];'
          'const bad=im.filter(i=>!(i.complete&&i.naturalWidth>0)).map(i=>i.getAttribute("src"));'
          'const p=document.createElement("pre");p.id="cdam-probe";'
          'p.textContent=JSON.stringify({images:im.length,missing:bad});'
          'document.body.appendChild(p);});</script>')


def browser() -> str:
    for b in BROWSERS:
        if shutil.which(b):
            return shutil.which(b)
    pytest.skip("no headless Chromium on PATH: `bash scripts/setup.sh --tests` installs "
                "chromium-headless-shell (apt)")


def _chromium(*args, timeout=120) -> subprocess.CompletedProcess:
    # root in a container: no setuid sandbox; no GPU here
    return subprocess.run([browser(), "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                           *args], capture_output=True, text=True, timeout=timeout)


def open_page(page: Path, shot: Path, width: int = 1100, height: int = 1400) -> dict:
    """Screenshot ``page`` into ``shot`` and return ``{"images": n, "missing": [src...],
    "shot": (height, width, channels), "shot_std": pixel std}``."""
    page = Path(page).resolve()
    r = _chromium(f"--screenshot={shot}", f"--window-size={width},{height}", page.as_uri())
    assert Path(shot).is_file(), f"no screenshot of {page}: {r.stderr[-1500:]}"
    import matplotlib.image as mpimg
    img = mpimg.imread(shot)
    probe = page.with_name("_probe_" + page.name)
    probe.write_text(page.read_text().replace("</body>", _PROBE + "</body>"))
    try:
        r = _chromium("--virtual-time-budget=10000", "--dump-dom", probe.as_uri())
    finally:
        probe.unlink()
    m = re.search(r'<pre id="cdam-probe">([^<]*)</pre>', r.stdout)
    assert m, f"the page {page} did not finish loading: {r.stderr[-1500:]}"
    out = json.loads(m.group(1))
    out["shot"] = img.shape
    out["shot_std"] = float(np.std(img[..., :3]))
    return out


def captions_follow_figures(html: str) -> bool:
    """Every image paragraph is followed by a caption paragraph in italics."""
    imgs = re.findall(r"<p><img[^>]*></p>\s*(<p>.{0,4})", html)
    return len(imgs) == html.count("<img") and all(c.startswith("<p><em>") for c in imgs)
