"""Systems under test for hazardhunt's own benchmarks, not part of the product's SUT: a
conservative controller no human can make fail and its mutants with one planted bug each
(``benchmarks/mutants.py``, docs/search-methods.md). They are plug-ins like a user's controller
(``--controller hazardhunt.benchmark.conservative:StaleTrack``); nothing in hazardhunt imports
them."""
