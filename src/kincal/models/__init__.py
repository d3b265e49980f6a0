"""Error models: how geometric errors of the chain are parametrised (one module each)."""
