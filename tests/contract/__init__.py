"""The contract every registered effect keeps, checked over ``clfx.plugins.discover()``:
unusual and non-finite pixel values, alpha 0, tiny and odd sizes, identity with a reason,
determinism across runs and thread counts, regions of definition and interest."""
