"""First-spike coding of spike streams (seed 000 §5.2): the ``.vfc`` container and its models."""

from viform.coding._compile_cache import install_locators as _install_locators

# before any kernel of the package is defined: their numba cache is stamped by every source file here
_install_locators()
