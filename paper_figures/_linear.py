"""Access to ``linear_case``'s public API for the linear-case figures (never a second implementation)."""

from ._jobs import needs


def linear_api(name: str):
    """``linear_case.<name>`` or a clear "needs linear_case.<name>" error."""
    try:
        import linear_case
    except ImportError as exc:
        raise needs(f"linear_case.{name}", "the closed forms of the paper's linear example") from exc
    fn = getattr(linear_case, name, None)
    if fn is None:
        raise needs(f"linear_case.{name}", "the closed forms of the paper's linear example")
    return fn
