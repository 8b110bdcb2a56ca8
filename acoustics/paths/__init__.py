"""Paths through a ray-traced scene: the Embree caster (``raycast``), scene meshes
(``meshes``), scattering laws (``scattering``) and what meshes add to a ping — occlusion,
multipath, reverberation, mesh targets (``ray_scene``)."""
