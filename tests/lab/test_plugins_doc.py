"""docs/plugins.md runs: its shell blocks, in order, in an empty folder, with what the page says
they print (the verdict, the mechanism, the fit to the floor, the one-line plugin errors)."""

import os
import re
import subprocess
import sys

import pytest

DOC = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "plugins.md")


def _blocks():
    with open(DOC) as f:
        text = f.read()
    return re.findall(r"```bash\n(.*?)```", text, flags=re.S)


@pytest.mark.slow
def test_plugins_page_runs_and_says_what_it_shows(tmp_path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.path.abspath(os.path.join(os.path.dirname(DOC), "..")),
                                                       os.environ.get("PYTHONPATH", "")]))
    bindir = os.path.dirname(sys.executable)
    env["PATH"] = bindir + os.pathsep + env.get("PATH", "")
    outs = []
    for block in _blocks():
        proc = subprocess.run(["bash", "-c", block], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=900)
        assert proc.returncode == 0, (block, proc.stderr[-2000:])
        outs.append(proc.stdout + proc.stderr)
    assert len(outs) == 6
    diagnose, fit, explained, bad = outs[1], outs[3], outs[4], outs[5]
    # not explained, the hidden layers fail, the mechanism is the activation's
    assert diagnose.startswith("NOT EXPLAINED"), diagnose[:400]
    assert "failing layers (one-step check, 0.01 with Bonferroni over the layers): 1, 2\n" in diagnose
    mech = diagnose.split("mechanisms the localised evidence points to")[1].splitlines()[1].split()
    assert mech[0] == "activation_mismatch", mech
    # the plugin's fit reaches the floor, and the hidden a2 = -0.0832 is recovered
    p_after = float(re.search(r"-> after [0-9.e+-]+ \+- [0-9.e+-]+ \(p = ([0-9.e+-]+)\)", fit).group(1))
    a2 = float(re.search(r"a2=(-?[0-9.e+-]+)\)", fit).group(1))
    assert p_after >= 0.01 and abs(a2 + 0.0832) < 0.02, fit
    assert explained.startswith("explained: awgn + act_shape"), explained[:300]
    # every bad plugin: one line naming the file, then exit 2
    lines = [l for l in bad.splitlines() if l]
    assert [l for l in lines if l.startswith("exit")] == ["exit 2"] * 4, bad
    for name, rule in (("broken.py", "syntax"), ("no_hook.py", "needs an activation"),
                       ("wrong_class.py", "must be one of the CONTRACTS"), ("clash.py", "clashes with the built-in")):
        msg = [l for l in lines if l.startswith(name + ":")]
        assert len(msg) == 1 and rule in msg[0], (name, bad)
    assert "Traceback" not in bad
