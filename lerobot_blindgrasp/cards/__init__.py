"""The cards: a dataset's (`dataset_cards.py`, sim demos and glove recordings alike), the shipped models'
(`model_cards.py`), and relative links made absolute from `[project.urls]` (`links.py`, which setup.py reads too)."""
