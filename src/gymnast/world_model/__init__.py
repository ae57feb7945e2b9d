"""World models: the `WorldModel` contract, the embedded CPU backend, its training and evaluation."""
