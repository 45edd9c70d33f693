"""The figure stage of a gift command on a timeline: each hand-over, each drawing this process
does (with its seconds), each drawing or netCDF the helper takes, and each netCDF written here.

    python stage_timeline.py diagnose FILE.npz --seed 4 --quiet --figures DIR
"""
import sys, time, os, io, contextlib, threading
T0 = time.perf_counter()
import gift_theory.lab._drawing as Dr
ev = []
oadd = Dr.Drawing.add
def add(self, jobs, *a):
    jobs = list(jobs)
    ev.append((time.perf_counter()-T0, "add", [os.path.basename(p) for _, p in jobs]))
    return oadd(self, jobs, *a)
Dr.Drawing.add = add
odh = Dr.Drawing._draw_here
def dh(self, i):
    t = time.perf_counter()-T0
    try: return odh(self, i)
    finally: ev.append((t, "main", os.path.basename(self.jobs[i][1]), round(time.perf_counter()-T0-t, 2)))
Dr.Drawing._draw_here = dh
otake = Dr.Drawing._take
def take(self, wait=False, here=False):
    i = otake(self, wait, here)
    if wait and i is not None: ev.append((time.perf_counter()-T0, "helper-take", os.path.basename(self.jobs[i][1])))
    return i
Dr.Drawing._take = take
ofin = Dr.Drawing.finish
def fin(self, meanwhile=None):
    ev.append((time.perf_counter()-T0, "finish-start"))
    if meanwhile is not None:
        m = meanwhile
        def meanwhile():
            t = time.perf_counter(); m(); ev.append((time.perf_counter()-T0, "meanwhile-done", round(time.perf_counter()-t, 2)))
    r = ofin(self, meanwhile); ev.append((time.perf_counter()-T0, "finish-end")); return r
Dr.Drawing.finish = fin
import gift_theory.lab._figure_sets as FS
osd = Dr.save_dataset
def sd(ds, path):
    t = time.perf_counter()-T0
    try: return osd(ds, path)
    finally: ev.append((t, "nc", os.path.basename(path), round(time.perf_counter()-T0-t, 3)))
Dr.save_dataset = sd
odf = FS.diagnosis_figures
def dfig(*a, **k):
    ev.append((time.perf_counter()-T0, "diagnosis_figures"))
    return odf(*a, **k)
FS.diagnosis_figures = dfig
from gift_theory.cli._main import main
try:
    with contextlib.redirect_stdout(io.StringIO()):
        main(sys.argv[1:])
finally:
    for e in sorted(ev, key=lambda e: e[0]): print(f"{e[0]:7.2f}", *e[1:], file=sys.stderr)
    print("end", time.perf_counter()-T0, file=sys.stderr)
