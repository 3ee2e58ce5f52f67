#!/usr/bin/env python3
"""Drives `gaia sim serve`'s page in headless Chromium as a person would, through the DevTools protocol (over a
pipe: --remote-debugging-pipe, so no extra library): it opens the page, holds keys for a number of frames each, and
prints one JSON line of what the page showed in each phase. Standard library only.

    drive_page.py URL PROFILE_DIR PHASE...      PHASE = KEYS:FRAMES, e.g. none:3 Shift+ArrowLeft:10

Output: {"phases": [{"keys": ..., "frames": N, "curvature": [commanded, 1/km], "read_back": [1/km or null],
"image": true}, ...]} or {"error": "..."} with a non-zero exit.
"""
import json, os, subprocess, sys, threading, time

KEYS = {"ArrowLeft": ("ArrowLeft", 37), "ArrowRight": ("ArrowRight", 39), "ArrowUp": ("ArrowUp", 38),
        "ArrowDown": ("ArrowDown", 40), "Shift": ("ShiftLeft", 16), " ": ("Space", 32)}


class DevTools:
    def __init__(self, profile):
        cmd_r, self.cmd_w = os.pipe()  # Chromium reads commands on its fd 3 and writes answers on its fd 4
        self.out_r, out_w = os.pipe()

        def fds():  # the pipe ends to fds 3 and 4, inheritable (the pipes themselves may be 3 and 4)
            a, b = os.dup(cmd_r), os.dup(out_w)
            os.dup2(a, 3)
            os.dup2(b, 4)
            os.set_inheritable(3, True)
            os.set_inheritable(4, True)
        self.proc = subprocess.Popen(["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                                      f"--user-data-dir={profile}", "--remote-debugging-pipe", "about:blank"],
                                     preexec_fn=fds, close_fds=False, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        os.close(cmd_r)
        os.close(out_w)
        self.next_id, self.answers, self.cv = 0, {}, threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        buf = b""
        while True:
            chunk = os.read(self.out_r, 65536)
            if not chunk:
                return
            buf += chunk
            while b"\0" in buf:
                msg, buf = buf.split(b"\0", 1)
                m = json.loads(msg)
                if "id" in m:
                    with self.cv:
                        self.answers[m["id"]] = m
                        self.cv.notify_all()

    def call(self, method, params=None, session=None, timeout=60):
        with self.cv:
            self.next_id += 1
            i = self.next_id
        msg = {"id": i, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self.cmd_w, json.dumps(msg).encode() + b"\0")
        with self.cv:
            if not self.cv.wait_for(lambda: i in self.answers, timeout):
                raise RuntimeError(f"no answer to {method} within {timeout} s")
            m = self.answers.pop(i)
        if "error" in m:
            raise RuntimeError(f"{method}: {m['error'].get('message')}")
        return m.get("result", {})

    def close(self):
        self.proc.kill()
        self.proc.wait()


def main():
    url, profile, phases = sys.argv[1], sys.argv[2], sys.argv[3:]
    dt = DevTools(profile)
    try:
        target = dt.call("Target.createTarget", {"url": url})["targetId"]
        s = dt.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]

        def js(expr):
            r = dt.call("Runtime.evaluate", {"expression": expr, "returnByValue": True}, s)
            if "exceptionDetails" in r:
                raise RuntimeError(f"page: {r['exceptionDetails'].get('text')}: {expr}")
            return r["result"].get("value")

        def key(kind, name, modifiers):
            code, vk = KEYS[name]
            dt.call("Input.dispatchKeyEvent", {"type": kind, "key": name, "code": code, "windowsVirtualKeyCode": vk,
                                               "nativeVirtualKeyCode": vk, "modifiers": modifiers}, s)

        deadline = time.time() + 60
        while js("typeof frames === 'number' ? frames : -1") < 1:  # the stream has started
            if time.time() > deadline:
                raise RuntimeError("no frame within 60 s: " + str(js("document.getElementById('error').textContent")))
            time.sleep(0.1)
        out = []
        for phase in phases:
            names, count = phase.rsplit(":", 1)
            held = [] if names == "none" else names.split("+")
            mods = 8 if "Shift" in held else 0
            for k in held:
                key("keyDown" if k != "Shift" else "rawKeyDown", k, mods)
            start = js("frames")
            while js("frames") < start + int(count):
                if time.time() > deadline + 300:
                    raise RuntimeError("frames stopped arriving")
                time.sleep(0.05)
            got = js("frames") - start
            out.append({"keys": names, "frames": got,
                        "curvature": js(f"state.curv.slice(-{got})"), "read_back": js(f"state.rcurv.slice(-{got})"),
                        "image": js("document.getElementById('frame').src.startsWith('data:image/png')")})
            for k in reversed(held):
                key("keyUp", k, 0)
        print(json.dumps({"phases": out}))
    except Exception as e:  # one line, for the test's failure message
        print(json.dumps({"error": str(e)}))
        sys.exit(1)
    finally:
        dt.close()


if __name__ == "__main__":
    main()
