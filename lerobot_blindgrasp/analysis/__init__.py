"""Table V (the paper's ablations) from a recipe's output folder (`table_v`, run by `scripts/paper_recipe.sh`). The
robot and the policy never import it; the research diagnosis tools live in the lab (`lab/diagnosis/`)."""
