"""hopnav's planning library: LTL, interval MDPs, products, synthesis, learned intervals.

Pure Python/numpy/scipy (and torch for the GP pieces); it never imports MuJoCo.
"""
