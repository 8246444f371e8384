"""Simulated hardware: emulators that speak the real protocols, and a camera
that renders the harp through a known lens at the simulated stage's angle."""
