"""Planning measurement campaigns: candidate poses, D-optimal selection, simulation."""
