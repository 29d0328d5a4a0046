"""The system under test: tracking, prediction, route, controllers (NMPC) and the safety layer."""
