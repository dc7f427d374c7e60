"""Simulation helpers shared by the tasks: furniture and free objects in a SAPIEN
scene, segmented point-cloud observations, and the scripted executor."""
