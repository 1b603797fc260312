"""hopnav's simulation side: the MuJoCo SLIP hopper, its learned controller and the runner."""
