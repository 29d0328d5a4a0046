"""The safety specification, the risk metric, the rewards and the episode outcomes (SPEC 4)."""
