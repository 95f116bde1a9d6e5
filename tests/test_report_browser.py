"""The report page in a real browser: headless Chromium loads it, its videos report a duration and a
playable state, the one control plays, pauses and seeks all videos together, every poster is the
worst-error frame, and a screenshot is not blank. Driven through the DevTools protocol over a pipe
(``--remote-debugging-pipe``: JSON messages separated by NUL on file descriptors 3 and 4), so no
extra package is needed."""

from __future__ import annotations

import base64
import fcntl
import io
import json
import os
import select
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from sidql.evaluation.report import report_clips
from sim.motion.synthetic import synthetic_motion
from sim.replay.render import RenderStyle

CHROMIUM = next(
    (shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)),
    None,
)

_PROBE = """
(async () => {
  if (document.readyState !== 'complete') {
    await new Promise(r => window.addEventListener('load', r, {once: true}));
  }
  const vids = Array.from(document.querySelectorAll('video'));
  const ready = v => new Promise(res => {
    if (v.readyState >= 3) return res();
    v.addEventListener('canplay', res, {once: true});
    v.addEventListener('error', res, {once: true});
  });
  await Promise.race([Promise.all(vids.map(ready)), new Promise(r => setTimeout(r, 30000))]);
  const out = [];
  for (const v of vids) {
    let played = false;
    try { await v.play(); await new Promise(r => setTimeout(r, 300)); played = !v.paused; }
    catch (e) { played = String(e); }
    out.push({duration: v.duration, readyState: v.readyState, error: v.error && v.error.code,
              width: v.videoWidth, height: v.videoHeight, played: played,
              currentTime: v.currentTime});
    v.pause();
  }
  return {videos: out, images: Array.from(document.images).map(i => i.naturalWidth),
          rows: document.querySelectorAll('table tr').length};
})()
"""


class DevTools:
    """Minimal Chrome DevTools protocol client over ``--remote-debugging-pipe``."""

    def __init__(self, url: str, profile: str, *, width=1280, height=1600):
        to_chrome_r, self._w = os.pipe()
        self._r, from_chrome_w = os.pipe()
        # move the child's ends above 4, so dup2 onto 3 and 4 never clobbers one with the other or
        # keeps a close-on-exec flag (dup2(3, 3) is a no-op): happens in a process with few fds open
        high = [fcntl.fcntl(fd, fcntl.F_DUPFD, 10) for fd in (to_chrome_r, from_chrome_w)]
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        to_chrome_r, from_chrome_w = high

        def fds():  # runs in the child: the pipe ends become fds 3 (read) and 4 (write)
            os.dup2(to_chrome_r, 3)
            os.dup2(from_chrome_w, 4)

        args = [
            CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
            "--no-first-run", "--disable-background-networking", "--disable-component-update",
            "--disable-sync", "--mute-audio", "--autoplay-policy=no-user-gesture-required",
            f"--user-data-dir={profile}", f"--window-size={width},{height}",
            "--remote-debugging-pipe", url,
        ]  # fmt: skip
        self.proc = subprocess.Popen(
            args, preexec_fn=fds, close_fds=False, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )  # fmt: skip
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self._buf = b""
        self._id = 0

    def call(self, method: str, params=None, session=None, timeout=60.0) -> dict:
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            while b"\0" in self._buf:
                raw, self._buf = self._buf.split(b"\0", 1)
                reply = json.loads(raw)
                if reply.get("id") == self._id:
                    if "error" in reply:
                        raise RuntimeError(f"{method}: {reply['error']}")
                    return reply["result"]
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._r], [], [], left)[0]:
                raise TimeoutError(f"no reply to {method} in {timeout} s")
            chunk = os.read(self._r, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed the pipe")
            self._buf += chunk

    def close(self):
        try:
            self.call("Browser.close", timeout=5)
        except (RuntimeError, TimeoutError, OSError):  # already gone
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._w)
        os.close(self._r)


@pytest.fixture(scope="module")
def report_dir(gl_context, tmp_path_factory):
    # skips only when no GL context exists (conftest.gl_context); errors of ours fail
    out = tmp_path_factory.mktemp("report")
    clip = synthetic_motion(1.0, seed=2)
    report_clips(
        [clip], out, W=4, methods=["uniform", "optimal"], style=RenderStyle(320, 240),
        title="browser test", progress=False, clip_numbers=[3],
    )  # fmt: skip
    return out


def test_report_files_and_checks(report_dir):
    checks = json.loads((report_dir / "checks.json").read_text())
    (clip,) = checks["clips"]
    assert [m["method"] for m in clip["methods"]] == ["uniform", "optimal"]
    for m in clip["methods"]:
        assert len(m["indices"]) == 4 and len(m["per_frame"]["mpjpe_mm"]) == clip["frames"]
        assert m["summary"]["bone_drift_max_mm"] < 1e-6
        assert set(m["excess"]) <= set(m["summary"])
        # files carry the clip's real number in its trial (3 here), not its place in the list
        assert (report_dir / f"clip03_{m['method']}.mp4").stat().st_size > 1000
        assert (report_dir / f"clip03_{m['method']}_keyframes.png").exists()
        assert (report_dir / f"clip03_{m['method']}_poster.jpg").exists()
    assert not list(report_dir.glob("clip00_*"))
    assert clip["clip"] == 3 and clip["original"]["summary"]["mpjpe_mm"] == 0.0
    page = (report_dir / "index.html").read_text()
    assert "http://" not in page and "https://" not in page  # needs no network
    assert "<h2>Clip 3:" in page and "Clip 0" not in page
    assert "frames (0-29)" in page  # numbered from 0


def test_best_value_per_column_and_declared_metrics():
    from sidql.evaluation.metrics import METRICS, Metric, best_rows, metric_value

    low = Metric("k", "k", "", "lower", "d", "{:.1f}")
    assert best_rows(low, [3.0, 1.0, None, 1.04, 2.0]) == {1, 3}  # equal as shown: 1.0
    assert best_rows(Metric("k", "k", "", "higher", "d", "{:.2f}"), [0.5, 0.9, 0.1]) == {1}
    zero = Metric("k", "k", "", "zero", "d", "{:+.1f}", excess=True)
    assert best_rows(zero, [-0.2, 3.0, 0.3, -5.0]) == {0}
    assert best_rows(low, [2.0, 2.0]) == set() and best_rows(low, [1.0, None]) == set()
    assert best_rows(Metric("k", "k", "", "", "d"), [1.0, 2.0]) == set()  # not ranked
    drift = next(m for m in METRICS if m.key == "bone_drift_max_mm")
    assert best_rows(drift, [4e-13, 2e-12, 5e-13]) == set()  # rounding, not a better method
    # excess metrics read the excess for methods; absent keys are n/a (None)
    assert metric_value(zero, {"k": 9.0}, {"k": -1.0}) == -1.0
    assert metric_value(zero, {"k": 9.0}) == 9.0 and metric_value(low, {}) is None
    keys = {m.key for m in METRICS}
    assert len(keys) == len(METRICS)
    assert {"penetration_mm", "float_mm", "skate_mm_s", "contact_precision", "contact_recall",
            "self_pen_excess_mm", "residual_force_bw", "joint_torque_rms_nm_kg"} <= keys  # fmt: skip
    assert all(m.better in ("lower", "higher", "zero", "original", "") for m in METRICS)
    # closeness to the original's value: the joint torque nearest the original's (0.35), not
    # the lowest (over-smoothed motion needs less)
    close = Metric("k", "k", "", "original", "d", "{:.2f}")
    assert best_rows(close, [0.30, 0.36, 0.45], original=0.35) == {1}
    # beyond the noise floor only: differences within it are no difference
    assert best_rows(low, [1.0, 1.3, 2.0], noise=0.5) == {0, 1}
    assert best_rows(low, [1.0, 1.3, 1.4], noise=0.5) == set()
    assert {"physdiff_penetrate_mm", "physdiff_float_mm", "physdiff_skate",
            "residual_torque_nm_kg"} <= keys  # fmt: skip


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    """Skip (saying why) only when no headless Chromium can be started and answer the DevTools
    protocol; everything after that probe fails the test instead."""
    if CHROMIUM is None:
        pytest.skip("chromium not installed (apt-get install chromium)")
    try:
        dt = DevTools("about:blank", str(tmp_path_factory.mktemp("probe")))
    except OSError as e:
        pytest.skip(f"cannot start {CHROMIUM}: {e}")
    try:
        dt.call("Browser.getVersion", timeout=30)
    except (RuntimeError, TimeoutError) as e:
        pytest.skip(f"{CHROMIUM} does not answer the DevTools protocol: {e}")
    finally:
        dt.close()
    return CHROMIUM


def run_in_page(report_dir: Path, profile: Path, expression: str, screenshot: bool = False):
    """Open the report's ``index.html`` in a fresh headless Chromium, await ``expression`` (a
    script returning a promise) there and return its value, with a base64 PNG screenshot taken
    afterwards when ``screenshot`` (else None)."""
    url = (report_dir / "index.html").resolve().as_uri()
    dt = DevTools("about:blank", str(profile))
    try:
        page = next(t for t in dt.call("Target.getTargets")["targetInfos"] if t["type"] == "page")
        session = dt.call("Target.attachToTarget", {"targetId": page["targetId"], "flatten": True})[
            "sessionId"
        ]
        dt.call("Page.navigate", {"url": url}, session)
        res = dt.call(
            "Runtime.evaluate",
            {"expression": expression, "awaitPromise": True, "returnByValue": True},
            session,
            timeout=90,
        )
        shot = None
        if screenshot:
            shot = dt.call("Page.captureScreenshot", {"format": "png"}, session)["data"]
        return res["result"]["value"], shot
    finally:
        dt.close()


def test_page_loads_in_chromium_with_playable_videos(browser, report_dir, tmp_path):
    state, shot = run_in_page(report_dir, tmp_path / "profile", _PROBE, screenshot=True)
    videos = state["videos"]
    assert len(videos) == 2
    for v in videos:
        assert v["error"] is None
        assert v["duration"] == pytest.approx(1.0, abs=0.1)  # 30 frames at 30 fps
        assert v["readyState"] >= 3  # HAVE_FUTURE_DATA: the browser can play it
        assert v["played"] is True and v["currentTime"] > 0  # it actually plays
        assert (v["width"], v["height"]) == (320, 240)
    assert all(w > 0 for w in state["images"]) and state["rows"] == 4
    img = np.asarray(Image.open(io.BytesIO(base64.b64decode(shot))).convert("L"), dtype=float)
    assert img.std() > 20  # not blank: text, table, video frames, plots


_SYNC = """
(async () => {
  if (document.readyState !== 'complete') {
    await new Promise(r => window.addEventListener('load', r, {once: true}));
  }
  const clip = document.querySelector('.clip');
  const vids = Array.from(clip.querySelectorAll('video'));
  await Promise.all(vids.map(v => v.readyState >= 3 ? 0 :
    new Promise(r => v.addEventListener('canplay', r, {once: true}))));
  const sleep = ms => new Promise(r => setTimeout(r, ms));
  const times = () => vids.map(v => v.currentTime);
  clip.querySelector('.play').click();
  await sleep(500);
  const playing = {times: times(), paused: vids.map(v => v.paused)};
  clip.querySelector('.play').click();
  await sleep(200);
  const paused = {times: times(), paused: vids.map(v => v.paused)};
  const seek = clip.querySelector('.seek');
  seek.value = 12;
  seek.dispatchEvent(new Event('input'));
  await sleep(300);
  const sought = {times: times(), label: clip.querySelector('.frame').textContent};
  const worst = clip.querySelector('[data-goto]');
  worst.click();
  await sleep(300);
  const posters = await Promise.all(vids.map(v => new Promise(res => {
    const im = new Image();
    im.onload = () => res({w: im.naturalWidth, h: im.naturalHeight, worst: +v.dataset.worst});
    im.onerror = () => res(null);
    im.src = v.poster;
  })));
  return {playing, paused, sought, posters, worstGoto: +worst.dataset.goto,
          afterWorst: times(), fps: +clip.dataset.fps};
})()
"""


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (apt-get install chromium)")
def test_one_control_plays_pauses_and_seeks_all_videos(report_dir, tmp_path):
    state, _ = run_in_page(report_dir, tmp_path / "profile", _SYNC)
    fps = state["fps"]
    assert fps == 30
    t = state["playing"]["times"]
    assert not any(state["playing"]["paused"]) and min(t) > 0.1  # all play from one button
    assert max(t) - min(t) <= 1.5 / fps  # together, within a frame and a half
    assert all(state["paused"]["paused"])
    assert max(state["paused"]["times"]) - min(state["paused"]["times"]) < 0.5 / fps
    # seeking to frame 12 (numbered from 0) puts every video in frame 12
    assert all(abs(x - 12.5 / fps) < 0.2 / fps for x in state["sought"]["times"])
    assert state["sought"]["label"] == "frame 12 of 0-29"
    # the link to the first method's worst frame moves all videos there
    w = state["worstGoto"]
    assert all(abs(x - (w + 0.5) / fps) < 0.2 / fps for x in state["afterWorst"])
    checks = json.loads((report_dir / "checks.json").read_text())
    for p, m in zip(state["posters"], checks["clips"][0]["methods"], strict=True):
        assert p is not None and (p["w"], p["h"]) == (320, 240)  # a real poster image
        assert p["worst"] == int(np.argmax(m["per_frame"]["mpjpe_mm"]))  # of the worst frame
