"""Studies of the measurement lab -- blind identification, null calibration, timing -- not library code.

Nothing in :mod:`gift_theory` imports from here. The studies talk to gift only through its
public API and its command line, and simulate chips with :mod:`studies.contract_sim`, a
plain-numpy transcription of reference §1-§3 written from the contract's text (not from
gift's forward pass), so that what they measure is gift against an independent reading of
the contract.

    python -m studies.blind write DIR [--physics builtin|open] ...   files from the independent simulator
    python -m studies.blind score DIR                                 gift diagnose on each, scored from labels
"""
