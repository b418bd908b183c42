/* The right-hand contents column: a long name in code type (a module path such as rfmap.solvers.cartodiffusion, a
   function name such as random_boundary_map(), a class name such as CartoDiffusionOptions) may wrap after a dot or
   an underscore, or between the words of a class name, instead of being broken in the middle of a word.  A <wbr>
   is only a place where the line may break: the text, and what is copied from it, stay as they are. */
function wrapTocNames() {
  document.querySelectorAll(".bd-sidebar-secondary .toc-entry code span.pre").forEach((span) => {
    const parts = span.textContent.split(/(?<=[._])(?=.)|(?<=[a-z])(?=[A-Z])/);
    if (parts.length < 2) {
      return;
    }
    span.textContent = "";
    parts.forEach((part, i) => {
      if (i > 0) {
        span.appendChild(document.createElement("wbr"));
      }
      span.appendChild(document.createTextNode(part));
    });
  });
}

if (document.readyState === "loading") {
  document.addEventListener("DOMContentLoaded", wrapTocNames);
} else {
  wrapTocNames();
}
