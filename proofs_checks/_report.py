"""The markdown report of ``gift check``: a summary table, then every record in full."""

from __future__ import annotations

import json


def one_line(text: str, width: int = 110) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= width else text[: width - 3] + "..."


def hypotheses_status(rec) -> str:
    """'k/n' hypotheses the verdict rests on verified by computation, then the counts of assumed
    hypotheses (never carrying a refutation) and of out-of-hypothesis instances reported as
    findings."""
    hs = rec.get("hypotheses") or []
    if not hs:
        return "-"
    need = [h for h in hs if h.get("needed_for_refutation", True)]
    ok = sum(1 for h in need if h.get("verified") is True)
    assumed = sum(1 for h in hs if h.get("assumed"))
    out = sum(1 for h in hs if not h.get("needed_for_refutation", True) and h.get("verified") is False)
    return (f"{ok}/{len(need)}" + (f" {assumed} assumed" if assumed else "")
            + (f" +{out} outside" if out else ""))


def render_table(records) -> str:
    """Plain-text table: id, verdict, hypotheses verified, one-line evidence."""
    w = max(len(r["id"]) for r in records)
    lines = [f"{'id':<{w}}  {'verdict':<12}  {'hypotheses':<22}  evidence", "-" * (w + 110)]
    lines += [f"{r['id']:<{w}}  {r['verdict']:<12}  {hypotheses_status(r):<22}  {one_line(r['evidence'], 90)}"
              for r in records]
    lines.append("hypotheses: computed-true / needed for a refutation; 'assumed' ones are not computed and never "
                 "carry a refutation; '+k outside': instances outside the statement, reported as findings")
    return "\n".join(lines)


def render_markdown(records, *, seconds: float | None = None, precise: bool = False) -> str:
    from ._record import ALPHA_CHECK, FAMILY_ALPHA

    lines = ["# gift check report", "",
             f"{len(records)} checks of the paper's printed statements "
             f"({'precise' if precise else 'default'} precision"
             + (f", {seconds:.0f} s" if seconds is not None else "") + "). "
             f"All numerical tests of one run together err with probability at most {FAMILY_ALPHA:g} (family-wise, "
             f"Bonferroni: {ALPHA_CHECK:g} per check, split over the check's tests as its evidence states).", "",
             "| id | verdict | hypotheses | evidence |", "|---|---|---|---|"]
    for r in records:
        lines.append(f"| `{r['id']}` | **{r['verdict']}** | {hypotheses_status(r)} | "
                     f"{one_line(r['evidence'], 160).replace('|', chr(92) + '|')} |")  # an escaped |, not a cell
    for r in records:
        lines += ["", f"## {r['id']}: {r['verdict']}", "", f"**Claim.** {r['claim']}", "",
                  f"**Evidence.** {r['evidence']}", ""]
        if r.get("hypotheses"):
            lines += ["**Hypotheses.**", ""]
            lines += [f"- {h['name']}: {h['statement']} -- "
                      f"{'verified' if h['verified'] else (('ASSUMED' if h.get('assumed') else 'not verified') if h['verified'] is None else 'FALSE')}"
                      f"{'' if h.get('needed_for_refutation', True) else ' (an instance reported as a finding)'}"
                      f"{': ' + h['detail'] if h.get('detail') else ''}".replace("\n", " ") for h in r["hypotheses"]]
            lines.append("")
        if r.get("correction"):
            lines += [f"**Correction (verified by this check).** {r['correction']}", ""]
        if r.get("counterexample") is not None:
            lines += ["**Counterexample / computed difference.**", "", "```json",
                      json.dumps(r["counterexample"], indent=2, default=float), "```"]
    return "\n".join(lines) + "\n"


def write_report(path: str, records, **kw) -> str:
    """Write the markdown report atomically (gift's one atomic writer: a temp file in the same
    folder, then a rename)."""
    from gift_theory import atomic_write_text

    return atomic_write_text(path, render_markdown(records, **kw))
