"""No import cycles in balance_calib: between modules, and between its folders (sub-packages).

Every import is counted, at the top of a module and inside functions alike (a lazy import hides a
cycle from Python, not from the reader): the folders show the pipeline, and imports point down it.
"""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / 'balance_calib'


def _modules(package: Path) -> dict[str, Path]:
    out = {}
    for path in package.rglob('*.py'):
        parts = path.relative_to(package.parent).with_suffix('').parts
        out['.'.join(parts[:-1] if parts[-1] == '__init__' else parts)] = path
    return out


def import_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """Module -> the package's modules it imports (relative and absolute, anywhere in the file)."""
    modules = _modules(package)
    graph = {name: set() for name in modules}
    for name, path in modules.items():
        here = name.split('.') if path.name == '__init__.py' else name.split('.')[:-1]
        for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
            if isinstance(node, ast.ImportFrom):
                base = here[: len(here) - node.level + 1] if node.level else []
                target = '.'.join(base + ([node.module] if node.module else []))
                names = [target] + [f'{target}.{alias.name}' for alias in node.names]
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            else:
                continue
            graph[name] |= {n for n in names if n in modules and n != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one node (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in graph.get(node, ()):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                other = stack.pop()
                on_stack.discard(other)
                component.append(other)
                if other == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in list(graph):
        if node not in index:
            visit(node)
    return found


def _folder(module: str) -> str:
    """balance_calib.fit.least_squares -> balance_calib.fit; a top-level module is its own node."""
    parts = module.split('.')
    return '.'.join(parts[:2])


def test_the_walker_finds_a_cycle_it_is_shown():
    assert cycles({'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}}) == [['a', 'b', 'c']]
    assert cycles({'a': {'b'}, 'b': set()}) == []


def test_the_walker_sees_imports_inside_functions_relative_and_absolute(tmp_path):
    package = tmp_path / 'pkg'
    (package / 'sub').mkdir(parents=True)
    (package / '__init__.py').write_text('')
    (package / 'sub' / '__init__.py').write_text('')
    (package / 'a.py').write_text('def f():\n    from .sub import b\n')
    (package / 'sub' / 'b.py').write_text('def g():\n    import pkg.a\n')
    graph = import_graph(package)
    assert graph['pkg.a'] == {'pkg.sub', 'pkg.sub.b'} and graph['pkg.sub.b'] == {'pkg.a'}
    assert cycles(graph) == [['pkg.a', 'pkg.sub.b']]


def test_no_module_imports_itself_back():
    assert cycles(import_graph()) == []


def test_no_folder_imports_itself_back():
    folders: dict[str, set[str]] = {}
    for module, targets in import_graph().items():
        folders.setdefault(_folder(module), set()).update(
            _folder(t) for t in targets if _folder(t) != _folder(module)
        )
    assert cycles(folders) == []
