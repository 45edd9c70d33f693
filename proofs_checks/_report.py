"""The markdown report of ``gift check``: a summary table, then every record in full."""

from __future__ import annotations

import json
import os
import tempfile


def one_line(text: str, width: int = 110) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= width else text[: width - 3] + "..."


def render_table(records) -> str:
    """Plain-text table: id, verdict, one-line evidence."""
    w = max(len(r["id"]) for r in records)
    lines = [f"{'id':<{w}}  {'verdict':<12}  evidence", "-" * (w + 80)]
    lines += [f"{r['id']:<{w}}  {r['verdict']:<12}  {one_line(r['evidence'])}" for r in records]
    return "\n".join(lines)


def render_markdown(records, *, seconds: float | None = None, precise: bool = False) -> str:
    lines = ["# gift check report", "",
             f"{len(records)} checks of the paper's printed statements "
             f"({'precise' if precise else 'default'} precision"
             + (f", {seconds:.0f} s" if seconds is not None else "") + "). "
             "Numerical tests use two-sided confidence 1 - 1e-5 unless stated.", "",
             "| id | verdict | evidence |", "|---|---|---|"]
    for r in records:
        lines.append(f"| `{r['id']}` | **{r['verdict']}** | {one_line(r['evidence'], 160).replace('|', '/')} |")
    for r in records:
        lines += ["", f"## {r['id']}: {r['verdict']}", "", f"**Claim.** {r['claim']}", "",
                  f"**Evidence.** {r['evidence']}", ""]
        if r.get("correction"):
            lines += [f"**Correction (verified by this check).** {r['correction']}", ""]
        if r.get("counterexample") is not None:
            lines += ["**Counterexample / computed difference.**", "", "```json",
                      json.dumps(r["counterexample"], indent=2, default=float), "```"]
    return "\n".join(lines) + "\n"


def write_report(path: str, records, **kw) -> str:
    """Write the markdown report atomically (temp file in the same folder, then os.replace)."""
    folder = os.path.dirname(os.path.abspath(path)) or "."
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".check_report.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(render_markdown(records, **kw))
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
