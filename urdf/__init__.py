"""Robot descriptions bundled with kincal (the EC66 of the paper)."""
