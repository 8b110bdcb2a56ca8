"""The base every layer may use: the data contract — its table (contract), the builder and check
every writer uses (groups), its I/O (dataset) and other layouts brought to it (convert) — the
configuration machinery (config), file safety (files: the one gate every user-supplied file
passes; atomic: outputs that appear whole or not at all), resource limits (resources), optional
dependencies (extras), lazy public names (lazy) and the counting volume (counting_volume), which
the simulator's ground truth shares."""
