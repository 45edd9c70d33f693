cd "$(dirname "$0")/../../.."  # the repository (a snapshot of bad9610 or later)
P=python; S=studies/results/2026-11-28/rule_g_T.py; H=${BLIND:-/tmp/h29}  # the blind sets, written as in section 3
$P $S $H/builtin_t/common_mode_0.npz 0 common_mode
$P $S $H/builtin_t/saturation_0.npz 0 saturation
$P $S $H/builtin_nt/common_mode_0.npz 0 common_mode
$P $S $H/builtin_nt/crosstalk_0.npz 0 crosstalk
$P $S $H/builtin_nt/saturation_0.npz 0 saturation
$P $S $H/builtin_nt/shot+crosstalk_0.npz 0 shot+crosstalk shot
$P $S $H/builtin_nt/weight_error_0.npz 0 weight_error
$P $S $H/drift_t/common_mode_0.npz 0 common_mode
$P $S $H/drift_t/common_mode_1.npz 0 common_mode
$P $S $H/drift_t/common_mode_2.npz 0 common_mode
$P $S $H/mesh_nt/mesh_loss_0.npz 0 layer_gain
$P $S $H/builtin_t/multiplicative+common_mode_1.npz 0 multiplicative multiplicative+common_mode
$P $S $H/builtin_t/multiplicative+common_mode_2.npz 0 multiplicative multiplicative+common_mode
$P $S $H/builtin_nt/multiplicative+common_mode_1.npz 0 multiplicative multiplicative+common_mode
