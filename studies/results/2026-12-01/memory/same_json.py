"""python same_json.py A.json B.json: whether two `gift diagnose --json` outputs are the same but for `seconds`."""
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
for d in (a, b):
    d.pop("seconds", None)
print("identical but seconds:", a == b)
