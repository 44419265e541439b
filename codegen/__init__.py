"""Model -> Q formats -> C text (pure functions). Stands on accelnav.model and accelnav.native only."""
