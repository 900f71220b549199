"""Grain-grain contacts: cell lists, the pair contact law, the sub-stepped contact phase, composite contacts."""
