"""The base every layer may use: the data contract and its I/O (dataset, convert), the
configuration machinery (config), file safety (atomic), resource limits (resources) and the
counting volume (counting_volume), which the simulator's ground truth shares."""
