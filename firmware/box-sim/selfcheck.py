#!/usr/bin/env python3
"""Self-check of the trigger-box firmware in box-sim, over its pty, as a host would drive it.

Starts box-sim (real time), opens its pty, checks the banner, the version reply, the answers to
good and bad lines, fires N camera pulses and measures from box-sim's trace (simulated time):
  - latency: end of the F line's last byte ('\\n', its stop bit) -> camera rising edge
  - pulse width, and the A timestamp against the edge (the box's clock against simulated time)
then a strobe flash, a busy fire, the e-stop and door inputs (report period, debounce, report
latency), the host-silence fail-safe and a firmware hang (box-sim --hang-at) that the watchdog
must end. Exit 0 when every check passes. Standard library only.

  python3 firmware/box-sim/selfcheck.py --box-sim target/firmware/box-sim \\
      --elf target/firmware/trigger-box.elf --out target/firmware/selfcheck [--fires 20]
"""

import argparse
import json
import os
import queue
import re
import select
import signal
import subprocess
import sys
import termios
import threading
import time

MAX_LINE = 64
ESTOP_AT = 4.0  # seconds of simulated time
ESTOP_RELEASE_AT = 4.5
DOOR_AT = 5.0
BOUNCE_US = 1000.0
LINE_RE = {
    "A": re.compile(r"^A (\d+) (\d+)$"),
    "E": re.compile(r"^E (\d+) (\d+)$"),
    "I": re.compile(r"^I (\d+) ([01]) ([01])$"),
    "V": re.compile(r"^V (\d+) (\d+) (\d+) (\d+\.\d+\.\d+)$"),
}


class Box:
    """The host side of the pty: a reader thread splits the box's output into lines."""

    def __init__(self, path):
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
        attrs = termios.tcgetattr(self.fd)
        attrs[0] = 0  # iflag
        attrs[1] = 0  # oflag
        attrs[2] = termios.CS8 | termios.CREAD | termios.CLOCAL
        attrs[3] = 0  # lflag: no echo, no canonical mode
        attrs[4] = attrs[5] = termios.B115200
        termios.tcsetattr(self.fd, termios.TCSANOW, attrs)  # TCSANOW: keep what is waiting
        self.lines = []  # (wall time, text) of every line, in order
        self.answers = queue.Queue()
        self.problems = []
        self.stop = False
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self):
        buf = b""
        while not self.stop:
            r, _, _ = select.select([self.fd], [], [], 0.05)
            if not r:
                continue
            try:
                chunk = os.read(self.fd, 4096)
            except OSError:
                return
            buf += chunk
            while b"\n" in buf:
                raw, buf = buf.split(b"\n", 1)
                now = time.monotonic()
                if len(raw) + 1 > MAX_LINE:
                    self.problems.append(f"line over {MAX_LINE} bytes: {raw!r}")
                try:
                    text = raw.decode("ascii").rstrip("\r")
                except UnicodeDecodeError:
                    self.problems.append(f"non-ASCII line {raw!r}")
                    continue
                self.lines.append((now, text))
                kind = text[:1]
                if kind == "#":
                    continue
                if kind not in LINE_RE or not LINE_RE[kind].match(text):
                    self.problems.append(f"line that does not parse: {text!r}")
                    continue
                if kind in "AEV":
                    self.answers.put(text)

    def send(self, text):
        os.write(self.fd, text.encode("ascii"))

    def command(self, text, timeout=1.0):
        """Send one command line and wait for its answer (A, E or V with its seq)."""
        seq = text.split()[1]
        self.send(text + "\n")
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"no answer to {text!r}")
            ans = self.answers.get(timeout=left)
            if ans.split()[1] == seq:
                return ans
            self.problems.append(f"answer {ans!r} while waiting for seq {seq}")

    def close(self):
        self.stop = True
        self.thread.join(timeout=1)
        os.close(self.fd)


def read_trace(path):
    rows = []
    with open(path) as f:
        header = f.readline().strip()
        assert header == "time_us,pin,level", header
        for line in f:
            t, pin, level = line.strip().split(",")
            rows.append((float(t), pin, int(level)))
    return rows


def host_lines(rows):
    """The host's lines as the box received them: (text, end time of its '\\n' in us)."""
    out, cur = [], bytearray()
    for t, pin, level in rows:
        if pin != "rx":
            continue
        if level == 10:
            out.append((cur.decode("ascii", "replace"), t))
            cur = bytearray()
        else:
            cur.append(level)
    return out


def box_lines(rows, frame_us):
    """The box's lines as sent: (text, start of its first byte, end of its '\\n'), in us."""
    out, cur, start = [], bytearray(), None
    for t, pin, level in rows:
        if pin != "tx":
            continue
        if start is None:
            start = t
        if level == 10:
            out.append((cur.decode("ascii", "replace"), start, t + frame_us))
            cur, start = bytearray(), None
        else:
            cur.append(level)
    return out


def edges(rows, pin):
    return [(t, level) for t, p, level in rows if p == pin]


def first_after(edge_list, t0, level):
    for t, lv in edge_list:
        if t >= t0 and lv == level:
            return t
    return None


def percentile(values, p):
    """Nearest-rank percentile."""
    s = sorted(values)
    k = max(0, min(len(s) - 1, int(-(-p * len(s) // 100)) - 1))
    return s[k]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--box-sim", default="target/firmware/box-sim")
    ap.add_argument("--elf", default="target/firmware/trigger-box.elf")
    ap.add_argument("--out", default="target/firmware/selfcheck")
    ap.add_argument("--fires", type=int, default=20)
    ap.add_argument("--fire-gap-ms", type=float, default=20.0, help="host pause between fires")
    args = ap.parse_args()

    os.makedirs(args.out, exist_ok=True)
    link = os.path.join(args.out, "box")
    trace_path = os.path.join(args.out, "trace.csv")
    log_path = os.path.join(args.out, "box-sim.log")
    failures = []

    def check(ok, what):
        print(("ok    " if ok else "FAIL  ") + what)
        if not ok:
            failures.append(what)

    # The fires, strobe and busy checks must be done before the e-stop is pressed.
    fire_time_s = args.fires * (args.fire_gap_ms + 4) / 1000
    t_estop, t_release, t_door = ESTOP_AT, ESTOP_RELEASE_AT, DOOR_AT
    if fire_time_s > 2.5:
        shift = fire_time_s - 2.0
        t_estop, t_release, t_door = t_estop + shift, t_release + shift, t_door + shift
    t_hang = t_door + 2.5

    log = open(log_path, "w")
    sim = subprocess.Popen(
        [args.box_sim, args.elf, "--link", link, "--trace", trace_path,
         "--press-estop-at", str(t_estop), "--release-estop-at", str(t_release),
         "--open-door-at", str(t_door), "--bounce-us", str(BOUNCE_US), "--hang-at", str(t_hang)],
        stderr=log)
    t_start = time.monotonic()
    try:
        for _ in range(200):
            if os.path.islink(link):
                break
            time.sleep(0.01)
        box = Box(link)
        time.sleep(0.3)

        # Banner, version, the protocol's commands.
        banner = [t for _, t in box.lines if t.startswith("#")]
        check(bool(banner) and re.match(r"^# hitl-trigger-box \d+\.\d+\.\d+ protocol 2 reset=power$",
                                        banner[0]) is not None,
              f"banner: {banner[0] if banner else None!r}")
        seq = 1
        ans = box.command(f"P {seq}")
        check(LINE_RE["A"].match(ans) is not None, f"P {seq} -> {ans!r}")
        seq += 1
        ver = box.command(f"V {seq}")
        m = LINE_RE["V"].match(ver)
        check(m is not None and m.group(3) == "2", f"V {seq} -> {ver!r}")
        seq += 1
        ans = box.command(f"L {seq} 650")
        check(ans.startswith(f"A {seq} "), f"L {seq} 650 -> {ans!r}")
        seq += 1
        ans = box.command(f"X {seq}")
        check(ans == f"E {seq} 2", f"X {seq} (unknown) -> {ans!r}")
        seq += 1
        ans = box.command(f"F {seq} 5")
        check(ans == f"E {seq} 1", f"F {seq} 5 (missing field) -> {ans!r}")
        seq += 1
        ans = box.command(f"F {seq} 5 4")
        check(ans == f"E {seq} 1", f"F {seq} 5 4 (bad mask) -> {ans!r}")
        seq += 1
        box.send("P " + "9" * 70 + "\n")
        ans = box.answers.get(timeout=1)
        check(ans == "E 0 1", f"a 72-byte line -> {ans!r}")
        box.send("\n")  # an empty line is ignored
        ans = box.command(f"P {seq}")
        check(ans.startswith(f"A {seq} "), f"empty line ignored, then P {seq} -> {ans!r}")
        seq += 1

        # The camera fires.
        fire_acks = {}
        for i in range(args.fires):
            ans = box.command(f"F {seq} {1000 + i} 1")
            m = LINE_RE["A"].match(ans)
            if m:
                fire_acks[seq] = int(m.group(2))
            else:
                failures.append(f"F {seq} -> {ans!r}")
            seq += 1
            time.sleep(args.fire_gap_ms / 1000)
        check(len(fire_acks) == args.fires, f"{args.fires} camera fires acknowledged")

        # Strobe: a 2 ms flash at full level, then an F with both lines (the last S's flash),
        # then a long flash and an F on the strobe during it: busy.
        strobe_seq = seq
        ans = box.command(f"S {seq} 1000 2000")
        check(ans.startswith(f"A {seq} "), f"S {seq} 1000 2000 -> {ans!r}")
        seq += 1
        time.sleep(0.01)
        both_seq = seq
        ans = box.command(f"F {seq} 2000 3")
        check(ans.startswith(f"A {seq} "), f"F {seq} 2000 3 -> {ans!r}")
        seq += 1
        time.sleep(0.01)
        ans = box.command(f"S {seq} 500 300000")
        check(ans.startswith(f"A {seq} "), f"S {seq} 500 300000 -> {ans!r}")
        seq += 1
        busy_seq = seq
        ans = box.command(f"F {seq} 2001 2")
        check(ans == f"E {seq} 3", f"F {seq} 2001 2 during the 300 ms flash -> {ans!r} (busy)")
        seq += 1
        ans = box.command(f"F {seq} 2002 1")
        check(ans.startswith(f"A {seq} "), f"F {seq} 2002 1 (camera only) during it -> {ans!r}")
        seq += 1

        # Inputs: keep the host alive (a ping every 200 ms) past the e-stop and door changes.
        while time.monotonic() - t_start < t_door + 0.3:
            box.command(f"P {seq}")
            seq += 1
            time.sleep(0.2)
        last_cmd_seq = seq - 1
        # Host silence: nothing for 1.5 s; the box goes safe after 1 s.
        time.sleep(1.5)
        silent = [t for _, t in box.lines if t == "# safe host-silent"]
        check(len(silent) == 1, "'# safe host-silent' after 1 s without a command")
        ans = box.command(f"P {seq}")
        check(ans.startswith(f"A {seq} "), f"a ping after the silence -> {ans!r}")
        seq += 1
        # A hang: light on, then the chip stops (box-sim --hang-at); the watchdog resets it.
        ans = box.command(f"L {seq} 500")
        check(ans.startswith(f"A {seq} "), f"L {seq} 500 -> {ans!r}")
        seq += 1
        hang_from_line = len(box.lines)
        while time.monotonic() - t_start < t_hang + 0.4:
            time.sleep(0.05)
        after = [t for _, t in box.lines[hang_from_line:]]
        check("# hitl-trigger-box 0.1.0 protocol 2 reset=watchdog" in after,
              "after the hang: banner with reset=watchdog")
        ans = box.command(f"P {seq}")
        m = LINE_RE["A"].match(ans)
        check(m is not None and int(m.group(2)) < 1_000_000,
              f"after the watchdog reset: P {seq} -> {ans!r} (the box's clock restarted)")
        seq += 1
        time.sleep(0.1)
        box.close()
    finally:
        sim.send_signal(signal.SIGTERM)
        try:
            rc = sim.wait(timeout=5)
        except subprocess.TimeoutExpired:
            sim.kill()
            rc = None
        log.close()
    check(rc == 0, f"box-sim exits 0 on SIGTERM (rc {rc})")
    check(not os.path.lexists(link), "box-sim removed its link")
    check(not box.problems, f"every line from the box parses ({box.problems[:3]})")

    rows = read_trace(trace_path)
    lines = host_lines(rows)
    cam = edges(rows, "camera")
    strobe = edges(rows, "strobe")
    light = edges(rows, "light")

    # Answer time: end of a command line -> end of its answer line on the wire.
    frame_us = 11 * 136 / 16  # simavr's frame: 11 bit times of 136 cycles
    rx_rows = [t for t, p, _ in rows if p == "rx"]
    frame_ok = all(b - a >= frame_us - 0.01 for a, b in zip(rx_rows, rx_rows[1:]))
    cmd_end = {}
    for text, end in lines:
        f = text.split()
        if len(f) >= 2 and f[1].isdigit() and f[0] in "PFLSV":
            cmd_end.setdefault(int(f[1]), end)
    answer_ms = []
    sent = box_lines(rows, frame_us)
    for text, _, end in sent:
        f = text.split()
        if f and f[0] in "AEV" and len(f) >= 2 and int(f[1]) in cmd_end:
            answer_ms.append((end - cmd_end[int(f[1])]) / 1000)
    check(frame_ok and answer_ms and max(answer_ms) <= 10,
          "answers: command's last byte -> answer's last byte p50 %.3f, max %.3f ms over %d "
          "(the protocol's bound: 10 ms)" % (percentile(answer_ms, 50), max(answer_ms),
                                             len(answer_ms)))

    # Latency and width of the camera fires.
    latency, width, offset = [], [], []
    fire_lines = {int(t.split()[1]): end for t, end in lines if t.startswith("F ")}
    for s, dev_us in fire_acks.items():
        nl = fire_lines[s]
        rise = first_after(cam, nl, 1)
        fall = first_after(cam, rise, 0) if rise is not None else None
        if rise is None or fall is None:
            failures.append(f"no camera pulse for F {s}")
            continue
        latency.append(rise - nl)
        width.append(fall - rise)
        offset.append(rise - dev_us)
    stats = {}
    if latency:
        stats = {
            "fires": len(latency),
            "latency_us": {"p50": percentile(latency, 50), "p99": percentile(latency, 99),
                           "max": max(latency), "min": min(latency)},
            "width_us": {"min": min(width), "max": max(width)},
            "ack_stamp_minus_edge_spread_us": max(offset) - min(offset),
        }
        lat = stats["latency_us"]
        check(lat["p99"] <= 100, "F line's last byte -> camera edge: p50 %.2f, p99 %.2f, max %.2f us "
              "(bound: p99 <= 100)" % (lat["p50"], lat["p99"], lat["max"]))
        check(all(abs(w - 1000) <= 1 for w in width),
              "camera pulse width %.4f..%.4f us (1000 +- 1)" % (min(width), max(width)))
        check(stats["ack_stamp_minus_edge_spread_us"] <= 2,
              "A timestamps track the edges: (edge - device_us) spread %.4f us (<= 2)"
              % stats["ack_stamp_minus_edge_spread_us"])
        off = sorted(offset)[len(offset) // 2]  # simulated us = device us + off (within the spread)
    cam_pulses = sum(1 for _, lv in cam if lv == 1)
    check(cam_pulses == args.fires + 2, f"camera pulses in the trace: {cam_pulses} "
          f"({args.fires} fires + F mask 3 + F mask 1 during the flash)")

    # Strobe flashes.
    s_nl = {int(t.split()[1]): end for t, end in lines if t.startswith("S ")}
    rise = first_after(strobe, s_nl[strobe_seq], 1)
    fall = first_after(strobe, rise, 0)
    check(fall is not None and abs((fall - rise) - 2000) <= 1,
          "S 1000 2000: strobe high %.4f us" % ((fall - rise) if fall else -1))
    lv_during = [lv for t, lv in light if rise - 20 <= t <= rise + 20]
    check(256 in lv_during, f"light at full (256/256) for the flash: {lv_during}")
    rise3 = first_after(strobe, fire_lines[both_seq], 1)
    cam3 = first_after(cam, fire_lines[both_seq], 1)
    fall3 = first_after(strobe, rise3, 0)
    check(rise3 == cam3 and fall3 is not None and abs((fall3 - rise3) - 2000) <= 1,
          "F mask 3: camera and strobe rise together, the strobe as the last S (2000 us)")
    rise_long = first_after(strobe, s_nl[busy_seq - 1], 1)
    fall_long = first_after(strobe, rise_long, 0)
    check(fall_long is not None and abs((fall_long - rise_long) - 300000) <= 1,
          "S 500 300000: strobe high %.4f us (held past 9 timer periods)"
          % ((fall_long - rise_long) if fall_long else -1))

    # The box's clock keeps time: an I line leaves the UART (simulated time) a little after its
    # device_us (formatting, and the answers queued ahead of it), never a timer period off.
    reset_at = [t for t, p, _ in rows if p == "reset"]
    i_off = [start - int(text.split()[1]) for text, start, _ in sent
             if text.startswith("I ") and (not reset_at or start < reset_at[0])]
    check(max(i_off) - min(i_off) < 10_000,
          "the box's clock against simulated time, over %d I lines: %.3f .. %.3f ms "
          "(a lost timer overflow would be 32.768 ms)" % (len(i_off), min(i_off) / 1000,
                                                        max(i_off) / 1000))

    # Inputs: report period, debounce, report latency (before the watchdog reset).
    inputs = [(t, text) for t, text in box.lines[:hang_from_line] if text.startswith("I ")]
    dev = [(int(x.split()[1]), int(x.split()[2]), int(x.split()[3])) for _, x in inputs]
    gaps = [b[0] - a[0] for a, b in zip(dev, dev[1:])]
    check(max(gaps) <= 50_000, f"I lines at most every 50 ms: largest gap {max(gaps) / 1000:.3f} ms "
          f"over {len(dev)} lines")

    def report_latency(bit, level, settle_s):
        for us, e, d in dev:
            if (e, d)[bit] == level and us + off >= settle_s * 1e6 - BOUNCE_US:
                return (us + off) - settle_s * 1e6
        return None

    # The contact settles BOUNCE_US after the change starts.
    lat_e = report_latency(0, 1, t_estop + BOUNCE_US / 1e6)
    lat_r = report_latency(0, 0, t_release + BOUNCE_US / 1e6)
    lat_d = report_latency(1, 1, t_door + BOUNCE_US / 1e6)
    check(lat_e is not None and 4000 <= lat_e <= 7000,
          f"e-stop pressed: reported {lat_e and lat_e / 1000:.3f} ms after the contact settled "
          "(5 samples 1 ms apart)")
    check(lat_r is not None and 4000 <= lat_r <= 7000,
          f"e-stop released: reported {lat_r and lat_r / 1000:.3f} ms after")
    check(lat_d is not None and 4000 <= lat_d <= 7000,
          f"door opened: reported {lat_d and lat_d / 1000:.3f} ms after")
    bounce_states = [(e, d) for us, e, d in dev
                     if t_estop * 1e6 <= us + off <= t_estop * 1e6 + BOUNCE_US + 4000]
    check(all(s == (0, 0) for s in bounce_states), "no report while the contact bounces")

    # Host silence: the light goes to its safe level (0) 1 s after the last command's end.
    last_nl = [end for t, end in lines if t.split()[1:2] == [str(last_cmd_seq)]][0]
    off_at = first_after(light, last_nl, 0)
    check(off_at is not None and 999_000 <= off_at - last_nl <= 1_002_000,
          "fail-safe: light off %.3f ms after the last command" % ((off_at - last_nl) / 1000
                                                                   if off_at else -1))
    check(all(lv == 0 for t, lv in cam if t >= last_nl), "camera line low through the silence")

    # Watchdog: the reset comes 120 ms (simavr: 128 ms) after the hang; the light is off from then.
    resets = [t for t, p, _ in rows if p == "reset"]
    check(len(resets) == 1 and 100_000 <= resets[0] - t_hang * 1e6 <= 150_000,
          "watchdog reset %.3f ms after the hang" % ((resets[0] - t_hang * 1e6) / 1000
                                                     if resets else -1))
    light_at_hang = [lv for t, lv in light if t <= t_hang * 1e6][-1]
    light_after = [lv for t, lv in light if t >= (resets[0] if resets else 0)]
    check(light_at_hang == 128 and light_after[:1] == [0],
          f"light {light_at_hang}/256 when it hung, {light_after[:1]} from the reset on")

    stats["answer_ms"] = {"p50": percentile(answer_ms, 50), "p99": percentile(answer_ms, 99),
                          "max": max(answer_ms), "count": len(answer_ms)}
    summary = {"stats": stats, "input_report_latency_ms": {
        "estop_pressed": lat_e and lat_e / 1000, "estop_released": lat_r and lat_r / 1000,
        "door_opened": lat_d and lat_d / 1000}, "largest_I_gap_ms": max(gaps) / 1000,
        "watchdog_reset_after_hang_ms": (resets[0] - t_hang * 1e6) / 1000 if resets else None,
        "version_reply": ver, "banner": banner[0] if banner else None, "failures": failures}
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    with open(log_path) as f:
        print(f.read().strip())
    print(f"selfcheck: {'FAILED: ' + str(len(failures)) if failures else 'all checks passed'}"
          f" (trace {trace_path}, summary {os.path.join(args.out, 'summary.json')})")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
