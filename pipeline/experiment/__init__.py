"""One episode's scenario, assembled from params below the stages: the typed settings, the
plant draw and the start and goal (used by the record stages and by identification)."""
