"""Signal features: statistics of a record's channels within its regimes' windows.

The stage beside :mod:`condmon.identify`: where identification turns a record
into physical parameters, this turns it into the statistics its declaration's
``[features]`` table names (:mod:`condmon.models.features`). Both are stored,
baselined, trended and checked alike.
"""

from condmon.features.compute import (
    FeatureEstimate, compute_features, feature_statistic, spans_for,
)

__all__ = ["FeatureEstimate", "compute_features", "feature_statistic", "spans_for"]
