"""The joint estimator: every factor, the hedgehog offset and the IPS latency from one or more
recordings of any motion (:func:`.estimate.estimate_joint`; the model and the sparse problem)."""
