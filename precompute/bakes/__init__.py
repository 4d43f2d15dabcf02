"""The bake: a material's SH coefficient tables, planned, computed and checked.

``planner`` chooses what a table holds (SH order, view, thickness and wavelength samples, the u
nodes) and its cache key; ``bake`` computes it in the factorised form, with ``kernel`` (the
film-free microfacet kernel), ``quadrature`` (Gauss–Legendre and spectral nodes), ``sh_order``
(the automatic SH order), ``chunks`` and ``progress`` (bounded steps between cancellation
checkpoints); ``bake_reference`` is the brute-force bake the tests compare with.
"""
