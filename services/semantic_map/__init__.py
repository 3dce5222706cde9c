"""The semantic map: artifacts and people with ids, fused from detections, persisted."""
