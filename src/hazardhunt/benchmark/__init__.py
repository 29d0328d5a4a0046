"""Systems under test for hazardhunt's own benchmarks, not part of the product's SUT: a
conservative controller no human can make fail and its mutants with one planted bug each
(:mod:`.conservative`; those written after the testers' defaults were settled, on which they
are judged and never tuned, in :mod:`.held_out`; ``benchmarks/mutants.py``,
docs/search-methods.md). They are plug-ins like a user's controller
(``--controller hazardhunt.benchmark.conservative:StaleTrack``); nothing in hazardhunt imports
them."""
