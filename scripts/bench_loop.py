"""The plain Python control loop of the xArm SDK's examples: sleep for the period, send, repeat.

Usage: bench_loop.py SECONDS RATE_HZ  -> prints one JSON object of wake-lateness figures (us),
measured against the absolute schedule start + k * period that hitl keeps.
"""
import json
import sys
import time

seconds, rate = float(sys.argv[1]), float(sys.argv[2])
period = 1.0 / rate
ticks = int(round(seconds * rate))
late = []
jitter = []
overruns = 0
start = time.monotonic()
prev = start
for k in range(1, ticks + 1):
    time.sleep(period)  # what the SDK examples do: sleep, then send
    now = time.monotonic()
    jitter.append(abs(now - prev - period))
    prev = now
    lateness = now - (start + k * period)
    late.append(max(lateness, 0.0))
    if lateness > period:
        overruns += 1
late.sort()
jitter.sort()


def at(p, xs=late):
    return xs[int(round((len(xs) - 1) * p))] * 1e6


print(json.dumps({
    "p50_us": at(0.5), "p99_us": at(0.99), "p999_us": at(0.999), "max_us": at(1.0),
    "interval_jitter_p99_us": at(0.99, jitter), "overruns": overruns, "ticks": len(late),
    "drift_ms": (time.monotonic() - start - ticks * period) * 1e3,
}))
