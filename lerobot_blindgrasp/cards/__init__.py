"""The cards: a dataset's (`dataset_cards.py`: sim teacher demos and glove teleoperation recordings alike, from
the templates in `card_templates/`) and the shipped models' (`model_cards.py`, with their one install section), and
relative links made absolute from `[project.urls]` for the Hub and the package index (`links.py`, which setup.py
also reads). Everything a card says is passed in or read from LeRobot's metadata: the demo collection builds its own
card's context (`demos/collection_card.py`)."""
