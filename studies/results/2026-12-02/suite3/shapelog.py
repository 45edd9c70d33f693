import os, json, atexit, math
SEEN = set()
def pytest_configure(config):
    import gift_theory._model as M
    orig = M._site_program
    def wrapped(key, tag, shape, law, dtype):
        SEEN.add((tuple(shape), None if law is None else getattr(law, "name", str(law)), str(dtype)))
        return orig(key, tag, shape, law, dtype)
    M._site_program = wrapped
    def dump():
        json.dump(sorted([list(s[0]), s[1], s[2]] for s in SEEN), open(f"/tmp/s3/shapes/{os.getpid()}.json", "w"))
    atexit.register(dump)
