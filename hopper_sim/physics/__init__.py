"""The MuJoCo hopper: its MJCF model, one hop, batched hops, terrain, noise, thrust."""
