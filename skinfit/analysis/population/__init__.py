"""The population (hierarchical) model over per-subject fits."""
