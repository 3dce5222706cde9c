"""The mission's behaviours: thin leaves that send goals and watch status."""
