"""What a person looks at: what static figures share (`plots`, matplotlib, PNG; each
experiment's figures are in a figure module beside it), rerun recordings (`viz`), the outlines
both draw (`shapes`) and progress on the terminal (`progress`).

matplotlib is imported only by `plots` and the experiments' figure modules, rerun only by `viz`.
"""
