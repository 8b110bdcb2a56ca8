"""The sonar: the ABACUS preset in numbers (``preset``), element arrays (``arrays``),
element-level Huygens directivity (``directivity``), beam patterns and widths (``beams``,
``beam_table``, ``plots``), the transmit pulse (``pulse``), the sonar assembled from a scene
(``build``), its absolute calibration (``calibration``) and geometry caches (``cache``)."""
