"""The physics twin's measurement campaign: the shipped student through the whole real stack on `blindgrasp-twin`
(`python -m lab.twin_campaign.measure`) and its record (`python -m lab.twin_campaign.report`). The twin itself, a
product command, stays in `lerobot_blindgrasp/twin/`."""
