"""Model file -> design numbers -> Q formats -> C text (pure functions), and the one cffi builder."""
