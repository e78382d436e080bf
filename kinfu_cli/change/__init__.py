"""What changed between two fused volumes of the same place: removed and added regions (`kinfu diff`)."""
