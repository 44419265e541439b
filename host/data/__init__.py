"""Files a user brings or keeps: recordings in (recording) and accelnav run files (runfile)."""
