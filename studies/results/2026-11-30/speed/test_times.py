"""A pytest plugin: each test's start and end time per xdist worker, written to
/tmp/testtimes_WORKER.json at the end of the run (how busy each worker was, and until when).

    PYTHONPATH=this_folder python -m pytest -n 2 -p test_times
"""
import os, time, json
_rows = []
def pytest_runtest_logstart(nodeid, location):
    _rows.append([nodeid, time.time(), None])
def pytest_runtest_logfinish(nodeid, location):
    for r in reversed(_rows):
        if r[0] == nodeid and r[2] is None:
            r[2] = time.time(); break
def pytest_unconfigure(config):
    w = os.environ.get("PYTEST_XDIST_WORKER", "main")
    json.dump(_rows, open(f"/tmp/testtimes_{w}.json", "w"))
