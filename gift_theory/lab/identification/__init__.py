"""Layer-wise system identification: each layer's effective transfer and noise, read off the shots.

With taps, layer l's measured output is regressed on the measured output of layer l-1 of the
*same shot* (layer 1: on x). Under reference §2 a tap is the value fed forward, so the
regressor of a shot is exactly the input its layer saw: the conditional mean of a_l given
a_{l-1} is the layer's mean map, with no error in the regressor (the noise of a_{l-1} is
part of the input, not an error of measuring it). Layer 1's input a_0 = x + n_a0 is not
measured: its noise enters the pre-activation as W n_a0 and is part of the model's noise.

Per layer (float64 numpy, closed form or a few Gauss-Newton steps, all neurons at once):

* **the mean map** ``W_eff, b_eff``: per neuron, least squares of the per-input mean output
  on the per-input mean of the linearised design ``sigma~'(z) [a, 1]`` (sigma~: the
  activation smoothed by the pre-activation's own noise, exact by Gauss-Hermite), iterated to
  the fixed point (Gauss-Newton). Its covariance is a sandwich whose meat is each input's
  within-cell covariance of the residuals across the layer's neurons (inputs are independent,
  neurons of one input are not), so every test below on it needs no assumed noise law;
* **restricted maps** on ``(W_eff - W, b_eff - b)`` by generalised least squares under that
  covariance: a gain (``W_eff = g W``), per-neuron bias shifts, a transfer of z (``g (W, b) + c``)
  and their combinations, and each neuron's own gain and shift of z (a detector's or
  modulator's gain and offset); the smallest one the data do not reject names the deviation;
* **dead or stuck neurons**: a row of W_eff indistinguishable from 0 where the programmed
  row is rejected;
* **the activation's shape**: binned means of the residual against the fitted z, shared by the
  layer's neurons, beyond each neuron's affine map (a function of z alone);
* **the noise**: its level per layer, its law (kurtosis of the standardised shots at equal
  variance), its dependence on the neuron's own signal and on the input's energy
  ``|a_{l-1}|^2``, the excess covariance across the layer's neurons within a shot (along the
  signal: a fluctuating gain; along the all-ones direction or anywhere else: correlated
  noise), and trends over acquisition time t (additive per neuron, a gain, a noise level).

Without taps the same is done at the output, its regressor the model's mean of a_{L-1} and
the noise of the hidden layers propagated to the output (Monte Carlo through the model, fixed
draws, at the level's fixed point): a deviation there is what every layer's deviation adds up
to, and docs/identification.md lists what cannot be separated.

Whether the map is the programmed one is a score test at the programmed map (no fit needed); a
layer with fewer inputs than its parameters per neuron (plus a margin) is not resolved: only
that test and the noise's are run there.

Every test returns a p-value (:func:`tests`: Holm-adjusted over classes x layers), an
effect size and its layer; :mod:`.._mechanisms` turns them into the ``mechanisms`` list.

Which module decides what:

=================  ==============================================================================
``_stats``         chi-square/F tails, per-input covariances of the residuals, the sandwich
                   covariance of the map, GLS of restricted maps, the sample kurtosis of r shots
``_layers``        what a layer's identification reads (taps: its regressor and shots; no taps:
                   the output with the hidden layers' noise propagated by Monte Carlo); the
                   model's mean, slope and variance per shot; the noise level's fixed point
``_map``           the map's fit, the score test of the programmed map, the shared shape of z,
                   a detector's gain and offset after the activation
``_map_rows``      the map's rows: dead neurons, the shape, the restricted map chosen (gain,
                   transfer, per-neuron gains, detector, bias shifts, weight error), the map's trend
``_noise``         the noise's rows: level, signal dependence, law, covariance across neurons,
                   trends of the noise within and across the inputs' shots
``_trend``         straight-line trends over acquisition time (within the shots; robust across them)
``_layer``         :func:`identify_layer`: one layer, composing the above with the time's terms
                   (``lab._time``: wander and drift) and memory (``lab._memory``)
``_network``       :func:`identify`: every layer (or the output), the equal-levels test
=================  ==============================================================================
"""

from .._smoothing import smoothed as smoothed
from ._layer import LayerIdentity as LayerIdentity
from ._layers import unit_variance as unit_variance
from ._network import CANNOT_SEPARATE_WITHOUT_TAPS as CANNOT_SEPARATE_WITHOUT_TAPS
from ._network import Identification as Identification
from ._network import identify as identify

__all__ = ["CANNOT_SEPARATE_WITHOUT_TAPS", "Identification", "LayerIdentity", "identify", "smoothed", "unit_variance"]
