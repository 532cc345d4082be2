"""The masks: clean, view-consistent object-ID maps for every view of a scene."""
