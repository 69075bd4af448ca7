"""The live view in a real headless browser (Playwright driving Debian's Chromium; nothing is
downloaded): ``labrig run --realtime --live --params`` on the simulated rig, the page opened
on the address it prints. Checked: the loop and the time series drawn (pixels of the measured
and the model colours in a screenshot of each plot) within 1 s of the first block, the update
rate, no error in the browser's console; then Ctrl-C of the run: exit 130, the amplifier at
0 V (the file's read-back after the ramp) and the page saying "aborted".

Marked ``browser`` (not in the default suite):
``pytest -m browser tests/runner/test_live_browser.py`` with
``pip install -e '.[test,browser]'`` and ``apt-get install chromium``.
"""

from __future__ import annotations

import io
import os
import select
import signal
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

pytestmark = [pytest.mark.browser, pytest.mark.timeout(180)]

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
ROOT = Path(__file__).resolve().parents[2]
PARAMS = ROOT / "experiments" / "hybrid-params.json"
MEASURED = (0x1F, 0x77, 0xB4)
MODEL = (0xFF, 0x7F, 0x0E)
#: what the measurements below found, for docs/live.md (printed with -s)
FOUND: dict[str, float] = {}


def coloured_pixels(png: bytes, rgb: tuple[int, int, int], tol: int = 40) -> int:
    from PIL import Image

    a = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    return int((np.abs(a - np.array(rgb)).sum(axis=2) < tol).sum())


@pytest.fixture
def browser(tmp_path: Path):
    sync_api = pytest.importorskip("playwright.sync_api", reason="pip install playwright")
    if not Path(CHROMIUM).exists():
        pytest.skip("no Chromium at /usr/bin/chromium (apt-get install chromium)")
    with sync_api.sync_playwright() as p:
        ctx = p.chromium.launch_persistent_context(
            str(tmp_path / "profile"),  # an empty user-data folder
            executable_path=CHROMIUM,
            headless=True,
            args=CHROMIUM_ARGS,
            viewport={"width": 1300, "height": 900},
        )
        try:
            yield ctx
        finally:
            ctx.close()


def start_run(tmp_path: Path) -> tuple[subprocess.Popen, str, Path]:
    proto = tmp_path / "live.yaml"
    proto.write_text(
        yaml.safe_dump(
            {
                "name": "live view test",
                "rate_hz": 1000,
                "steps": [
                    {"kind": "sine", "amplitude_V": 100, "frequency_hz": 2, "duration_s": 20},
                    {"kind": "sine", "amplitude_V": 50, "frequency_hz": 5, "duration_s": 5},
                ],
            }
        )
    )
    out = tmp_path / "live.h5"
    cmd = [sys.executable, "-m", "labrig.cli", "run", str(proto), "--out", str(out)]
    cmd += ["--realtime", "--seed", "1", "--live", "--params", str(PARAMS)]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stderr], [], [], 1.0)
        line = proc.stderr.readline() if ready else ""
        if line.startswith("live view: "):
            return proc, line.split(": ", 1)[1].strip(), out
        assert proc.poll() is None, proc.stderr.read()
    proc.kill()
    pytest.fail("labrig run --live printed no address")


def iso_epoch(text: str) -> float:
    return datetime.fromisoformat(text).timestamp()


def test_live_page_draws_the_run_and_shows_how_it_ended(browser, tmp_path: Path):
    errors: list[str] = []
    page = browser.new_page()
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    proc, url, out = start_run(tmp_path)
    try:
        assert url.startswith("http://127.0.0.1:")
        page.goto(url)
        page.wait_for_function("window.labrigLive.firstDataDraw !== null", timeout=30_000)
        first_draw_s = page.evaluate("window.labrigLive.firstDataDraw") / 1e3
        time.sleep(3.0)  # let it draw for a while
        draws = np.array(page.evaluate("window.labrigLive.drawTimes"), dtype=float) / 1e3
        loop_png = page.locator("#loop").screenshot()
        strain_png = page.locator("#strain").screenshot()
        voltage_png = page.locator("#voltage").screenshot()
        page.screenshot(path=str(tmp_path / "live.png"))
        doc = page.evaluate("window.labrigLive.doc")

        proc.send_signal(signal.SIGINT)  # Ctrl-C of the run
        code = proc.wait(timeout=60)
        page.wait_for_function(
            "document.getElementById('status').textContent.includes('aborted')", timeout=10_000
        )
        status_text = page.locator("#status").inner_text()
        amp_text = page.locator("#amplifier").inner_text()
        time.sleep(0.5)  # any late console error
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()

    # the run ended as Ctrl-C ends a run: 130, aborted, the amplifier read back at 0 V
    assert code == 130
    with h5py.File(out) as f:
        assert f["run/status"][()] == b"aborted"
        assert f["run/final_amplifier_voltage_V"][()] == 0.0
        first_block_s = iso_epoch(f["sine_100V_2Hz/start_time"][()].decode()) + 0.1
    assert "aborted" in status_text and "Ctrl-C" in status_text
    assert "0.000 V" in amp_text

    # drawn within 1 s of the first block (written 0.1 s after the entry's start)
    latency = first_draw_s - first_block_s
    FOUND["first_draw_latency_s"] = latency
    assert latency < 1.0, latency
    # updated at least 5 times a second while the run was going
    recent = draws[draws > draws[-1] - 2.5]
    rate = (recent.size - 1) / (recent[-1] - recent[0])
    FOUND["updates_per_s"] = rate
    assert rate >= 5.0, rate
    # the plots show data: measured and model curves in the loop and the strain series
    assert coloured_pixels(loop_png, MEASURED) > 300
    assert coloured_pixels(loop_png, MODEL) > 100
    assert coloured_pixels(strain_png, MEASURED) > 300
    assert coloured_pixels(strain_png, MODEL) > 100
    assert coloured_pixels(voltage_png, (0x2C, 0xA0, 0x2C)) > 300
    assert doc["status"] == "running" and doc["entry"]["samples"] > 1000
    assert doc["progress"]["planned"] == 2
    assert errors == []
    print(f"\nlive view: {FOUND}")
    if os.environ.get("LABRIG_LIVE_SCREENSHOT"):
        Path(os.environ["LABRIG_LIVE_SCREENSHOT"]).write_bytes((tmp_path / "live.png").read_bytes())
