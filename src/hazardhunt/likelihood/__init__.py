"""How likely a failure is: a model of the people on the floor and of the SUT's uncertainties,
and estimators of the probability of a failure per encounter under them (``hazardhunt
estimate``)."""
