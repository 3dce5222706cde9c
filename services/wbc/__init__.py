"""Whole-body control: the robot model per tick, tasks, constraints, the QP, the gait."""
