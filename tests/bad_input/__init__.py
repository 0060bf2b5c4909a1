"""Bad input a user can give woody, one module per family, each case through the real entry point.

A package (with this file) so its modules are imported as ``bad_input.<name>`` and their names
(``test_meshes``, ``conftest``) do not clash with the package tests of the same name.
"""
