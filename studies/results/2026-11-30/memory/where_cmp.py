import sys, pickle, numpy as np
a, b = pickle.load(open(sys.argv[1], "rb")), pickle.load(open(sys.argv[2], "rb"))
def eq(x, y, path=""):
    if isinstance(x, dict):
        assert set(x) == set(y), path
        return all(eq(x[k], y[k], f"{path}/{k}") for k in x)
    if isinstance(x, (list, tuple)):
        return len(x) == len(y) and all(eq(u, v, f"{path}[{i}]") for i, (u, v) in enumerate(zip(x, y)))
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        ok = np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
    else:
        ok = (x == y) or (x != x and y != y)
    if not ok: print("DIFF at", path)
    return ok
print(sys.argv[1], "IDENTICAL" if eq(a, b) else "DIFFERENT")
