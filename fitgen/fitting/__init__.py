"""From data to a model: the stepwise AIC search, the device's noise as rows, families, held-out figures, a unit's identification and capture schedules."""
