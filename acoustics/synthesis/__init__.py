"""Per-element echo synthesis: virtual scatterers (``scatterers``) → arrivals at every
receiver element (``arrivals``, compiled maths in ``kernels``) → complex baseband samples
(``synthesize``) → receiver noise and ADC (``receiver``)."""
