"""Point targets (fish, squid) of a ping: explicit points and random populations (``draw``)."""
