"""Tables, statistics, plots and reports from stored results."""
