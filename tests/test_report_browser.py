"""The report page in a real browser: headless Chromium loads it, its videos report a duration and a
playable state, and a screenshot is not blank. Driven through the DevTools protocol over a pipe
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

import numpy as np
import pytest

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
        except Exception:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._w)
        os.close(self._r)


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory):
    from sidql.evaluation.report import report_clips
    from sim.motion.synthetic import synthetic_motion

    try:
        from sim.replay.render import SkeletonRenderer

        SkeletonRenderer(("root", "a"), np.array([-1, 0]), RenderStyle(64, 48)).close()
    except Exception as e:
        pytest.skip(f"offscreen rendering unavailable (MUJOCO_GL=egl): {e}")
    out = tmp_path_factory.mktemp("report")
    clip = synthetic_motion(1.0, seed=2)
    report_clips(
        [clip], out, W=4, methods=["uniform", "optimal"], style=RenderStyle(320, 240),
        title="browser test", progress=False,
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
        assert (report_dir / f"clip00_{m['method']}.mp4").stat().st_size > 1000
        assert (report_dir / f"clip00_{m['method']}_keyframes.png").exists()
    assert clip["original"]["summary"]["mpjpe_mm"] == 0.0
    page = (report_dir / "index.html").read_text()
    assert "http://" not in page and "https://" not in page  # needs no network


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (apt-get install chromium)")
def test_page_loads_in_chromium_with_playable_videos(report_dir, tmp_path):
    from PIL import Image

    url = (report_dir / "index.html").resolve().as_uri()
    dt = DevTools("about:blank", str(tmp_path / "profile"))
    try:
        page = next(t for t in dt.call("Target.getTargets")["targetInfos"] if t["type"] == "page")
        session = dt.call("Target.attachToTarget", {"targetId": page["targetId"], "flatten": True})[
            "sessionId"
        ]
        dt.call("Page.navigate", {"url": url}, session)
        res = dt.call(
            "Runtime.evaluate",
            {"expression": _PROBE, "awaitPromise": True, "returnByValue": True},
            session,
            timeout=90,
        )
        state = res["result"]["value"]
        shot = dt.call("Page.captureScreenshot", {"format": "png"}, session)["data"]
    finally:
        dt.close()
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
