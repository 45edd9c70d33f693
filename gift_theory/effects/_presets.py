"""Preset chips: the effects two common kinds of photonic hardware are known for, to start from.

A preset names *which* effects a kind of chip shows, after the papers below; its *levels* are
orders of magnitude chosen for a small simulated chip with weights of order one, not values
those papers measured. Fit them to a measurement of your chip (``gift fit --add``) before you
trust them; ``gift simulate --preset NAME`` draws a measurement from one, ``--effect`` changes a
level (``gift simulate --preset coherent-mzi-mesh --effect shot=0.02``).
"""

from __future__ import annotations

#: name -> what it is, its effects (make_effect's keywords) and where the effects come from
PRESETS: dict[str, dict] = {
    "coherent-mzi-mesh": {
        "description": "a coherent chip: each weight matrix programmed as the phases of a Mach-Zehnder "
                       "interferometer mesh, outputs read by photodetectors",
        "effects": {"awgn": {"s": 0.02},
                    "weight_error": {"e": 0.02, "seed": 0},
                    "crosstalk": {"k": 0.01},
                    "shot": {"q": 0.005},
                    "quantization": {"bits": 8.0, "v_range": 2.0}},
        "sources": ("phase-encoding errors and photodetection noise limit a coherent mesh: Shen et al., "
                    "Nature Photonics 11, 441 (2017); imprecise beam splitters and phase shifters make the "
                    "realised matrix differ from the programmed one: Fang et al., Optics Express 27, 14009 "
                    "(2019); thermal crosstalk between neighbouring phase shifters: the crosstalk effect"),
    },
    "incoherent-intensity": {
        "description": "an incoherent chip: weights as the transmissions of intensity modulators (microring "
                       "weight banks, phase-change cells), products summed on photodiodes",
        "effects": {"awgn": {"s": 0.02},
                    "common_mode": {"c": 0.02},
                    "shot": {"q": 0.01},
                    "saturation": {"v_max": 2.0},
                    "quantization": {"bits": 6.0, "v_range": 2.0}},
        "sources": ("broadcast-and-weight microring banks sum on balanced photodiodes (shot noise, the "
                    "laser's relative intensity noise shared by a layer's channels): Tait et al., Sci. Rep. "
                    "7, 7430 (2017); phase-change cells hold a few bits per weight and the readout "
                    "saturates: Feldmann et al., Nature 589, 52 (2021)"),
    },
}


def preset_effects(name: str, where: str = "--preset") -> dict:
    """The effects of preset ``name`` (``{effect: {param: value}}``); an unknown name is a bad input."""
    from .._errors import GiftInputError

    if name not in PRESETS:
        raise GiftInputError(f"{where}: unknown preset {name!r}; known: {', '.join(PRESETS)}")
    return {k: dict(v) for k, v in PRESETS[name]["effects"].items()}
