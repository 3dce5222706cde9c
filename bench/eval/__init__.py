"""`dume eval`: seeded worlds, one bring-me request each, judged from the simulator's truth.

`run` watches one request on a live stack, `judge` compares it with the truth, `targets`
chooses what to ask for from the map, `report` writes the tables and plots, `evaluate`
runs the worlds.
"""
