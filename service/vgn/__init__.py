"""The network itself: its layers, a faster equivalent form, weights loading, micro-batching and
grasp detection on its output."""
