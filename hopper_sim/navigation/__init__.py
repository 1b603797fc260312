"""The navigation loop: the environment (physics in a scenario's world), the runner, its events."""
