"""The headline experiment: the papers' comparison on the real world (`gymnast experiment`)."""
