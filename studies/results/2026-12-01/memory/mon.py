"""python mon.py LOG cmd... : run cmd, sample its RSS every 0.1 s, log stderr lines with times; print per-stage peaks."""
import subprocess, sys, threading, time
log = open(sys.argv[1], "w")
p = subprocess.Popen(sys.argv[2:], stderr=subprocess.PIPE, text=True)
t0 = time.time(); events = []
def reader():
    for line in p.stderr:
        events.append((time.time() - t0, line.rstrip()))
threading.Thread(target=reader, daemon=True).start()
samples = []
while p.poll() is None:
    try:
        for l in open(f"/proc/{p.pid}/status"):
            if l.startswith("VmRSS"):
                samples.append((time.time() - t0, int(l.split()[1]) / 1e6))
    except FileNotFoundError:
        break
    time.sleep(0.1)
time.sleep(0.2)
ev = events + [(1e9, "END")]
prev = (0.0, "START")
for tt, line in ev:
    seg = [s for t_, s in samples if prev[0] <= t_ < tt]
    print(f"{prev[0]:7.1f}s peak {max(seg) if seg else 0:5.2f} GB  {prev[1][:110]}", file=log)
    prev = (tt, line)
log.close()
print("max", max(s for _, s in samples), file=sys.stderr)
