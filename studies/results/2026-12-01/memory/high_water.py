"""python high_water.py RUN.bin DEPTH: the live allocations at a memray capture's high-water mark, by Python stack
(DEPTH frames), largest first; allocations with no Python frame (XLA's threads) in one row."""
import sys, collections, memray
r = memray.FileReader(sys.argv[1])
recs = list(r.get_high_watermark_allocation_records(merge_threads=True))
tot = sum(a.size for a in recs)
print(f"high watermark live {tot/1e6:.0f} MB in {len(recs)} records")
by = collections.Counter()
for a in recs:
    st = a.stack_trace(max_stacks=12)
    key = " <- ".join(f"{f[0]}:{f[1].split('/')[-1]}:{f[2]}" for f in st[:int(sys.argv[2]) if len(sys.argv)>2 else 4]) or "<native/no python>"
    by[key] += a.size
for k, v in by.most_common(25):
    print(f"{v/1e6:8.1f} MB  {k}")
