"""The package's own files as the packaging tests read them: the launch file's syntax tree, setup.py's keywords."""
import ast
import glob
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGE = "cemnet_ros"
LAUNCH_FILE = REPO / "launch" / "align_node.launch.py"
RVIZ_FILE = REPO / "rviz" / "cemnet_ros.rviz"


def launch_tree() -> ast.Module:
    return ast.parse(LAUNCH_FILE.read_text(), filename=str(LAUNCH_FILE))


def setup_keyword(name: str):
    """A keyword of setup(), evaluated for the forms setup.py uses: literals, names, `+`, glob("pattern")."""
    tree = ast.parse((REPO / "setup.py").read_text())
    names = {target.id: node.value.value for node in tree.body if isinstance(node, ast.Assign)
             and isinstance(node.value, ast.Constant) for target in node.targets}

    def evaluate(node):
        if isinstance(node, ast.Name):
            return names[node.id]
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
            return evaluate(node.left) + evaluate(node.right)
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "glob":
            return sorted(glob.glob(node.args[0].value, root_dir=REPO))
        if isinstance(node, (ast.List, ast.Tuple)):
            return [evaluate(element) for element in node.elts]
        if isinstance(node, ast.Dict):
            return {evaluate(key): evaluate(value) for key, value in zip(node.keys, node.values)}
        return ast.literal_eval(node)

    (setup,) = calls(tree, "setup")
    return evaluate(keyword(setup, name))


def calls(tree: ast.AST, name: str) -> list:
    """Calls of `name(...)` or `anything.name(...)`."""
    return [node for node in ast.walk(tree) if isinstance(node, ast.Call)
            and name in (getattr(node.func, "id", None), getattr(node.func, "attr", None))]


def keyword(call: ast.Call, name: str):
    return next((keyword.value for keyword in call.keywords if keyword.arg == name), None)


def constant(node):
    return node.value if isinstance(node, ast.Constant) else None
