"""Analysis tools that read policies, datasets and evaluations; nothing in the training or robot path imports them."""
