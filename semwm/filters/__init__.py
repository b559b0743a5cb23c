"""Motion models, Kalman and IMM filters (scalar and batched) and the filter factory."""

from semwm.filters.factory import ClassFilter, FilterFactory, build_class_filter

__all__ = ["ClassFilter", "FilterFactory", "build_class_filter"]
