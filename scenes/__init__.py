"""The scene files shipped with abacus (installed as the package ``abacus_scenes``).

Run one by name (``abacus run default``) or by path (``abacus run scenes/default.yaml``);
:func:`acoustics.scene.builtin.builtin_scene` finds them wherever abacus is installed.
"""
