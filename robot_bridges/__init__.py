"""Robot bridges: one sub-package per back end (nextage_sim, vplus, kuka_rsi) and the bridge port."""
