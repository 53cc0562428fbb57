"""Learning: the family agents (observation scaling, action in mm, policy-file loader) and their training."""
