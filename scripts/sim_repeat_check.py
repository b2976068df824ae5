"""Compare two `hitl run --clock sim` recordings topic by topic (docs/sim-clock.md): the payloads
the simulated clock repeats exactly, hashed in the order they were written. Exit 1 if any differ.

usage: sim_repeat_check.py A.mcap B.mcap
"""
import sys, hashlib
from mcap.reader import make_reader
TOP = ("/arm/state", "/arm/setpoint", "/camera/", "/pose/gt", "/pose/estimate")
def digest(p):
    d = {}
    with open(p, "rb") as f:
        for _, ch, m in make_reader(f).iter_messages():
            if ch.topic.startswith(TOP):
                h = d.setdefault(ch.topic, [hashlib.sha256(), 0])
                h[0].update(m.data); h[1] += 1
    return {k: (v[0].hexdigest()[:16], v[1]) for k, v in sorted(d.items())}
a, b = digest(sys.argv[1]), digest(sys.argv[2])
for k in sorted(set(a) | set(b)):
    print(("same " if a.get(k) == b.get(k) else "DIFF ") + k, a.get(k), b.get(k))
sys.exit(0 if a == b else 1)
